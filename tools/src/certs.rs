//! `session certs`: what a session across machines needs to know who is who. A session CA; a
//! certificate per site (common name = the site's name), one for the launcher and one per router,
//! each signed by the CA and good for both ends of a TLS link (a station listens and connects);
//! and the access control that follows from the scenario ([`coop_transport::acl`]), which names
//! those common names.
//!
//! Keys are ECDSA P-256, made by rcgen with the `ring` backend: ring is already in the build for
//! zenoh's rustls, so this adds no second crypto library (aws-lc is C-built and large).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context};
use coop_transport::acl::{self, Members};
use rcgen::{
    BasicConstraints, CertificateParams, DnType, ExtendedKeyUsagePurpose, IsCa, Issuer, KeyPair,
    KeyUsagePurpose, PKCS_ECDSA_P256_SHA256,
};

/// What to make.
#[derive(Debug, Clone)]
pub struct CertsArgs {
    /// Session name (the access control's keys).
    pub session: String,
    /// The scenario's site names.
    pub sites: Vec<String>,
    /// The routers' names.
    pub routers: Vec<String>,
    /// Per name, the addresses and host names it is reached at (added to its certificate's
    /// subject alternative names, next to its name, `localhost`, 127.0.0.1 and ::1).
    pub hosts: BTreeMap<String, Vec<String>>,
    /// Days the certificates are valid.
    pub days: u32,
    /// Output directory (made if absent).
    pub out: PathBuf,
    /// The ROS 2 domain the stations publish in (`--ros2-domain`), if they do.
    pub ros2_domain: Option<u32>,
    /// ROS 2 tools that may look at the domain through the routers (`--ros2-viewer`), each with a
    /// certificate of its own.
    pub ros2_viewers: Vec<String>,
}

/// What was written.
#[derive(Debug, Clone)]
pub struct Written {
    /// The CA certificate (what every side trusts).
    pub ca: PathBuf,
    /// Per common name: certificate and key.
    pub certs: BTreeMap<String, (PathBuf, PathBuf)>,
    /// The access control.
    pub acl: PathBuf,
}

fn name_rule(what: &str, n: &str) -> anyhow::Result<()> {
    if n.is_empty()
        || n.len() > 64
        || !n
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_')
    {
        bail!("{what} {n:?}: a certificate's common name here is 1 to 64 letters, digits, - or _");
    }
    Ok(())
}

fn write_private(path: &Path, text: &str) -> anyhow::Result<()> {
    use std::io::Write;
    use std::os::unix::fs::OpenOptionsExt;
    let mut f = std::fs::OpenOptions::new()
        .write(true)
        .create(true)
        .truncate(true)
        .mode(0o600)
        .open(path)
        .with_context(|| format!("writing {}", path.display()))?;
    f.write_all(text.as_bytes())
        .with_context(|| format!("writing {}", path.display()))
}

/// Makes the CA, the certificates and the access control in `a.out`.
///
/// # Errors
/// A name that cannot be a common name, a name used twice (a router named like a site), an
/// address rcgen refuses, or a file that cannot be written.
pub fn make(a: &CertsArgs) -> anyhow::Result<Written> {
    let mut names: Vec<String> = a.sites.clone();
    names.push(acl::LAUNCHER.to_owned());
    names.extend(a.routers.iter().cloned());
    if !a.ros2_viewers.is_empty() && a.ros2_domain.is_none() {
        bail!("--ros2-viewer without --ros2-domain: a viewer looks at a ROS 2 domain");
    }
    if let Some(d) = a
        .ros2_domain
        .filter(|&d| d > coop_transport::ros2::MAX_DOMAIN_ID)
    {
        bail!(
            "--ros2-domain {d}: must be 0..={} (ROS 2's range)",
            coop_transport::ros2::MAX_DOMAIN_ID
        );
    }
    if a.ros2_domain.is_some() {
        coop_transport::ros2::check_names(a.sites.iter().map(String::as_str), [])
            .map_err(|e| anyhow::anyhow!("--ros2-domain: {e}"))?;
    }
    names.extend(a.ros2_viewers.iter().cloned());
    for (i, n) in names.iter().enumerate() {
        name_rule("name", n)?;
        if names[..i].contains(n) {
            bail!("name {n:?} is used twice (sites, `launcher`, the routers and the ROS 2 viewers need distinct names: the access control tells them apart by it)");
        }
    }
    for h in a.hosts.keys() {
        if !names.contains(h) {
            bail!(
                "--host {h}=…: {h:?} is no site, router or the launcher (names: {})",
                names.join(", ")
            );
        }
    }
    if !(1..=3650).contains(&a.days) {
        bail!("--days {}: must be from 1 to 3650", a.days);
    }
    std::fs::create_dir_all(&a.out).with_context(|| format!("making {}", a.out.display()))?;
    let now = time::OffsetDateTime::now_utc();
    let (from, to) = (
        now - time::Duration::hours(1),
        now + time::Duration::days(i64::from(a.days)),
    );

    let ca_key = KeyPair::generate_for(&PKCS_ECDSA_P256_SHA256)?;
    let mut ca = CertificateParams::new(Vec::<String>::new())?;
    ca.distinguished_name
        .push(DnType::CommonName, format!("coop session {} CA", a.session));
    ca.is_ca = IsCa::Ca(BasicConstraints::Constrained(0));
    ca.key_usages = vec![KeyUsagePurpose::KeyCertSign, KeyUsagePurpose::CrlSign];
    ca.not_before = from;
    ca.not_after = to;
    let ca_cert = ca.self_signed(&ca_key)?;
    let ca_path = a.out.join("ca.pem");
    std::fs::write(&ca_path, ca_cert.pem())
        .with_context(|| format!("writing {}", ca_path.display()))?;
    write_private(&a.out.join("ca.key"), &ca_key.serialize_pem())?;
    let issuer = Issuer::new(ca, ca_key);

    let mut certs = BTreeMap::new();
    for n in &names {
        let mut sans = vec![
            n.clone(),
            "localhost".to_owned(),
            "127.0.0.1".to_owned(),
            "::1".to_owned(),
        ];
        sans.extend(a.hosts.get(n).into_iter().flatten().cloned());
        let mut p = CertificateParams::new(sans.clone())
            .with_context(|| format!("the names and addresses of {n}: {}", sans.join(", ")))?;
        p.distinguished_name.push(DnType::CommonName, n.as_str());
        p.key_usages = vec![KeyUsagePurpose::DigitalSignature];
        p.extended_key_usages = vec![
            ExtendedKeyUsagePurpose::ServerAuth,
            ExtendedKeyUsagePurpose::ClientAuth,
        ];
        p.use_authority_key_identifier_extension = true;
        p.not_before = from;
        p.not_after = to;
        let key = KeyPair::generate_for(&PKCS_ECDSA_P256_SHA256)?;
        let cert = p.signed_by(&key, &issuer)?;
        let (cp, kp) = (
            a.out.join(format!("{n}.pem")),
            a.out.join(format!("{n}.key")),
        );
        std::fs::write(&cp, cert.pem()).with_context(|| format!("writing {}", cp.display()))?;
        write_private(&kp, &key.serialize_pem())?;
        certs.insert(n.clone(), (cp, kp));
    }
    let acl_value = acl::session_acl(&Members {
        session: &a.session,
        sites: &a.sites,
        launcher: acl::LAUNCHER,
        routers: &a.routers,
        ros2: a.ros2_domain.map(|domain| acl::Ros2Members {
            domain,
            viewers: &a.ros2_viewers,
        }),
    });
    let acl_path = a.out.join("acl.json5");
    std::fs::write(&acl_path, serde_json::to_string_pretty(&acl_value)? + "\n")
        .with_context(|| format!("writing {}", acl_path.display()))?;
    Ok(Written {
        ca: ca_path,
        certs,
        acl: acl_path,
    })
}

/// Parses `NAME=ADDR[,ADDR…]`.
///
/// # Errors
/// A message naming the value and the form.
pub fn parse_host(s: &str) -> Result<(String, Vec<String>), String> {
    let (n, addrs) = s
        .split_once('=')
        .filter(|(n, a)| !n.is_empty() && !a.is_empty())
        .ok_or_else(|| format!("{s:?}: use NAME=ADDR[,ADDR…], e.g. r1=192.0.2.1"))?;
    Ok((
        n.to_owned(),
        addrs.split(',').map(|a| a.trim().to_owned()).collect(),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_session_gets_a_ca_a_certificate_per_name_and_its_acl() {
        let out = std::env::temp_dir().join(format!("coop-certs-{}", std::process::id()));
        let a = CertsArgs {
            session: "s1".into(),
            sites: vec!["user1".into(), "user2".into()],
            routers: vec!["r1".into()],
            hosts: BTreeMap::from([("r1".to_owned(), vec!["192.0.2.1".to_owned()])]),
            days: 2,
            out: out.clone(),
            ros2_domain: None,
            ros2_viewers: Vec::new(),
        };
        let w = make(&a).expect("certs");
        let names: Vec<&str> = w.certs.keys().map(String::as_str).collect();
        assert_eq!(names, ["launcher", "r1", "user1", "user2"]);
        let pem = std::fs::read_to_string(&w.certs["user1"].0).expect("cert");
        assert!(pem.starts_with("-----BEGIN CERTIFICATE-----"), "{pem}");
        use std::os::unix::fs::PermissionsExt;
        let mode = std::fs::metadata(&w.certs["user1"].1)
            .expect("key")
            .permissions()
            .mode();
        assert_eq!(
            mode & 0o077,
            0,
            "a private key is the owner's only: {mode:o}"
        );
        let acl: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&w.acl).expect("acl")).expect("json");
        assert_eq!(acl["default_permission"], "deny");
        let mut bad = a.clone();
        bad.routers = vec!["user2".into()];
        let e = make(&bad).expect_err("a router named like a site");
        assert!(
            format!("{e:#}").contains("name \"user2\" is used twice"),
            "{e:#}"
        );
        bad = a.clone();
        bad.hosts = BTreeMap::from([("r9".to_owned(), vec!["192.0.2.1".to_owned()])]);
        assert!(format!("{:#}", make(&bad).expect_err("unknown host name"))
            .contains("\"r9\" is no site"));
        assert!(parse_host("r1").is_err());
        assert_eq!(
            parse_host("r1=192.0.2.1,192.0.2.5"),
            Ok(("r1".into(), vec!["192.0.2.1".into(), "192.0.2.5".into()]))
        );
        let _ = std::fs::remove_dir_all(&out);
    }
}
