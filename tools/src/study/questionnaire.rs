//! The questionnaire each participant answers after each block: NASA-TLX's six scales (Hart &
//! Staveland 1988; 0–100 in steps of 5, the raw TLX: no pairwise weighting, as most studies now
//! use it, Hart 2006) and Likert items of the study's own (co-presence, say), as a form in a
//! browser; the answers checked and kept one row per item.

use serde::{Deserialize, Serialize};

/// The study file's `[questionnaire]`.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct QuestionnaireSpec {
    /// Ask NASA-TLX's six scales.
    #[serde(default = "yes")]
    pub nasa_tlx: bool,
    /// Items of the study's own.
    #[serde(default)]
    pub item: Vec<ItemSpec>,
}

fn yes() -> bool {
    true
}

/// One Likert item.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct ItemSpec {
    /// Its name (a value of the answers' `item` column: A-Z a-z 0-9 _).
    pub name: String,
    /// The statement the participant rates.
    pub text: String,
    /// The scale's points, 2 to 11 (7: 1 to 7).
    #[serde(default = "seven")]
    pub points: u32,
    /// The label of its lowest point.
    #[serde(default = "disagree")]
    pub low: String,
    /// The label of its highest point.
    #[serde(default = "agree")]
    pub high: String,
}

fn seven() -> u32 {
    7
}

fn disagree() -> String {
    "strongly disagree".into()
}

fn agree() -> String {
    "strongly agree".into()
}

/// NASA-TLX's scales: name, question, low and high labels (Hart & Staveland 1988).
pub const TLX: [(&str, &str, &str, &str); 6] = [
    (
        "tlx_mental",
        "Mental demand: how mentally demanding was the task?",
        "very low",
        "very high",
    ),
    (
        "tlx_physical",
        "Physical demand: how physically demanding was the task?",
        "very low",
        "very high",
    ),
    (
        "tlx_temporal",
        "Temporal demand: how hurried or rushed was the pace of the task?",
        "very low",
        "very high",
    ),
    (
        "tlx_performance",
        "Performance: how successful were you in accomplishing what you were asked to do?",
        "perfect",
        "failure",
    ),
    (
        "tlx_effort",
        "Effort: how hard did you have to work to accomplish your level of performance?",
        "very low",
        "very high",
    ),
    (
        "tlx_frustration",
        "Frustration: how insecure, discouraged, irritated, stressed and annoyed were you?",
        "very low",
        "very high",
    ),
];

/// One question as asked: name, text, lowest and highest value, step, labels.
#[derive(Debug, Clone, PartialEq)]
pub struct Question {
    /// Its name.
    pub name: String,
    /// Its text.
    pub text: String,
    /// Lowest and highest value, and the step between values.
    pub range: (u32, u32, u32),
    /// Labels of the ends.
    pub labels: (String, String),
}

impl QuestionnaireSpec {
    /// The questions, in the order asked.
    pub fn questions(&self) -> Vec<Question> {
        let mut out: Vec<Question> = Vec::new();
        if self.nasa_tlx {
            out.extend(TLX.iter().map(|(n, t, lo, hi)| Question {
                name: (*n).into(),
                text: (*t).into(),
                range: (0, 100, 5),
                labels: ((*lo).into(), (*hi).into()),
            }));
        }
        out.extend(self.item.iter().map(|i| Question {
            name: i.name.clone(),
            text: i.text.clone(),
            range: (1, i.points, 1),
            labels: (i.low.clone(), i.high.clone()),
        }));
        out
    }

    /// Its rules: at least one question, item names unique and not a TLX scale's, 2 to 11 points.
    ///
    /// # Errors
    /// The rule broken, naming the field and the value.
    pub fn check(&self) -> Result<(), String> {
        if !self.nasa_tlx && self.item.is_empty() {
            return Err(
                "questionnaire: ask something: nasa_tlx = true or a [[questionnaire.item]]".into(),
            );
        }
        let mut seen: Vec<&str> = TLX.iter().map(|t| t.0).collect();
        for (k, i) in self.item.iter().enumerate() {
            let ok = !i.name.is_empty()
                && i.name
                    .chars()
                    .all(|c| c.is_ascii_alphanumeric() || c == '_');
            if !ok || seen.contains(&i.name.as_str()) {
                return Err(format!("questionnaire.item[{k}].name = {:?}: use 1 or more of A-Z a-z 0-9 _, unique, not a TLX scale's name", i.name));
            }
            seen.push(&i.name);
            if !(2..=11).contains(&i.points) {
                return Err(format!(
                    "questionnaire.item[{k}].points = {}: a scale of 2 to 11 points",
                    i.points
                ));
            }
            if i.text.trim().is_empty() {
                return Err(format!(
                    "questionnaire.item[{k}].text: the statement to rate"
                ));
            }
        }
        Ok(())
    }

    /// The answers of a submitted form (`application/x-www-form-urlencoded`): every question
    /// answered once with a value on its scale, nothing else.
    ///
    /// # Errors
    /// What is wrong, for the participant to see.
    pub fn parse_answers(&self, body: &str) -> Result<Vec<(String, u32)>, String> {
        let questions = self.questions();
        let mut got: Vec<(String, u32)> = Vec::new();
        for pair in body.split('&').filter(|p| !p.is_empty()) {
            let (k, v) = pair.split_once('=').unwrap_or((pair, ""));
            let (k, v) = (url_decode(k)?, url_decode(v)?);
            let Some(q) = questions.iter().find(|q| q.name == k) else {
                return Err(format!("{k:?} is not a question of this questionnaire"));
            };
            if got.iter().any(|(n, _)| *n == k) {
                return Err(format!("{k:?} answered twice"));
            }
            let value: u32 = v
                .parse()
                .map_err(|_| format!("{k}: {v:?} is not a whole number"))?;
            let (lo, hi, step) = q.range;
            if value < lo || value > hi || !(value - lo).is_multiple_of(step) {
                return Err(format!(
                    "{k}: {value} is not on its scale ({lo} to {hi} in steps of {step})"
                ));
            }
            got.push((k, value));
        }
        if let Some(q) = questions
            .iter()
            .find(|q| !got.iter().any(|(n, _)| *n == q.name))
        {
            return Err(format!("{:?} is not answered", q.name));
        }
        got.sort_by_key(|(n, _)| questions.iter().position(|q| q.name == *n));
        Ok(got)
    }

    /// The form for block `block`, as an HTML fragment posting to `action`. Every question
    /// starts unanswered (a slider would send its preset middle for a scale left alone).
    pub fn form(&self, action: &str, block: usize) -> String {
        use std::fmt::Write;
        let mut out = format!(
            "<form method=\"post\" action=\"{}\">\n<input type=\"hidden\" name=\"block\" value=\"{block}\">\n",
            html(action)
        );
        for q in self.questions() {
            let (lo, hi, step) = q.range;
            let _ = writeln!(out, "<fieldset><legend>{}</legend>", html(&q.text));
            let _ = write!(out, "<span>{}</span> ", html(&q.labels.0));
            if step == 1 {
                for v in lo..=hi {
                    let _ = write!(
                        out,
                        "<label><input type=\"radio\" name=\"{0}\" value=\"{v}\" id=\"{0}-{v}\" required>{v}</label> ",
                        html(&q.name)
                    );
                }
            } else {
                let _ = write!(
                    out,
                    "<input type=\"number\" name=\"{0}\" id=\"{0}\" min=\"{lo}\" max=\"{hi}\" step=\"{step}\" required>",
                    html(&q.name)
                );
            }
            let _ = writeln!(out, " <span>{}</span></fieldset>", html(&q.labels.1));
        }
        out.push_str("<button type=\"submit\" id=\"submit\">Send</button>\n</form>\n");
        out
    }
}

/// `s` with `&`, `<`, `>`, `"` and `'` escaped for HTML.
pub fn html(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            c => out.push(c),
        }
    }
    out
}

/// Decodes a form field (`+` a space, `%XX` a byte), which must be UTF-8.
///
/// # Errors
/// A malformed escape or bytes that are not UTF-8.
pub fn url_decode(s: &str) -> Result<String, String> {
    let mut bytes = Vec::with_capacity(s.len());
    let mut it = s.bytes();
    while let Some(b) = it.next() {
        match b {
            b'+' => bytes.push(b' '),
            b'%' => {
                let hex = [it.next(), it.next()];
                let v = match hex {
                    [Some(a), Some(b)] => std::str::from_utf8(&[a, b])
                        .ok()
                        .and_then(|h| u8::from_str_radix(h, 16).ok()),
                    _ => None,
                };
                bytes.push(v.ok_or_else(|| format!("{s:?}: a malformed %-escape"))?);
            }
            b => bytes.push(b),
        }
    }
    String::from_utf8(bytes).map_err(|_| format!("{s:?}: not UTF-8"))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spec() -> QuestionnaireSpec {
        QuestionnaireSpec {
            nasa_tlx: true,
            item: vec![ItemSpec {
                name: "copresence".into(),
                text: "I felt my partner was with me".into(),
                points: 7,
                low: disagree(),
                high: agree(),
            }],
        }
    }

    #[test]
    fn answers_are_every_question_once_on_its_scale() {
        let s = spec();
        let all = "tlx_mental=50&tlx_physical=0&tlx_temporal=100&tlx_performance=25&tlx_effort=75&tlx_frustration=5&copresence=6";
        let a = s.parse_answers(all).expect("valid");
        assert_eq!(a.len(), 7);
        assert_eq!(a[6], ("copresence".into(), 6));
        for (bad, says) in [
            (
                all.replace("copresence=6", "copresence=8"),
                "not on its scale",
            ),
            (
                all.replace("tlx_mental=50", "tlx_mental=52"),
                "not on its scale",
            ),
            (all.replace("&copresence=6", ""), "not answered"),
            (format!("{all}&copresence=5"), "answered twice"),
            (format!("{all}&x=1"), "not a question"),
            (all.replace("tlx_effort=75", "tlx_effort=%ZZ"), "malformed"),
            (
                all.replace("tlx_effort=75", "tlx_effort=-5"),
                "whole number",
            ),
        ] {
            let e = s.parse_answers(&bad).expect_err(&bad);
            assert!(e.contains(says), "{bad}: {e}");
        }
    }

    #[test]
    fn the_form_escapes_and_asks_everything() {
        let mut s = spec();
        s.item[0].text = "<b>partner</b> & \"me\"".into();
        let f = s.form("/q/p1", 3);
        assert!(f.contains("&lt;b&gt;partner&lt;/b&gt; &amp; &quot;me&quot;"));
        assert_eq!(f.matches("type=\"number\"").count(), 6);
        assert!(f.contains("name=\"block\" value=\"3\""));
        assert!(!f.contains("value=\"50\""), "no scale starts answered");
        assert_eq!(f.matches("type=\"radio\"").count(), 7);
        assert!(s.check().is_ok());
        s.item[0].name = "tlx_mental".into();
        assert!(s.check().is_err());
    }
}
