//! The orders a group does its conditions in.
//!
//! A Williams design (Williams 1949) is a Latin square balanced for first-order carry-over: each
//! condition comes once in every position and, for an even number of conditions, right after
//! every other condition exactly once (for an odd number the square and its mirror together
//! balance it, so twice as many rows). Group `g` takes row `g` modulo the rows: a study whose
//! groups are a multiple of the rows is balanced.

/// The number of rows a Williams design of `n` conditions has.
pub fn williams_rows(n: usize) -> usize {
    if n.is_multiple_of(2) {
        n
    } else {
        2 * n
    }
}

/// Row `row` (modulo [`williams_rows`]) of the Williams design of `n` conditions: the order of
/// conditions 0..n.
pub fn williams(n: usize, row: usize) -> Vec<usize> {
    if n == 0 {
        return Vec::new();
    }
    // The first row: 0, 1, n−1, 2, n−2, ...; row r adds r to every entry (modulo n).
    let mut first = Vec::with_capacity(n);
    first.push(0);
    let (mut lo, mut hi) = (1, n);
    for k in 1..n {
        if k % 2 == 1 {
            first.push(lo);
            lo += 1;
        } else {
            hi -= 1;
            first.push(hi);
        }
    }
    let rows = williams_rows(n);
    let r = row % rows;
    let mut out: Vec<usize> = first.iter().map(|c| (c + r % n) % n).collect();
    if r >= n {
        out.reverse();
    }
    out
}

/// Conditions 0..n shuffled (Fisher–Yates) with a generator seeded by `seed`.
pub fn shuffled(n: usize, seed: u64) -> Vec<usize> {
    let mut out: Vec<usize> = (0..n).collect();
    let mut state = seed;
    let mut next = || {
        state = super::mix(state, &[]);
        state
    };
    for i in (1..n).rev() {
        let j = (next() % (i as u64 + 1)) as usize;
        out.swap(i, j);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every condition once per position; every ordered pair of neighbours `per_pair` times.
    fn check(n: usize) {
        let rows: Vec<Vec<usize>> = (0..williams_rows(n)).map(|r| williams(n, r)).collect();
        for pos in 0..n {
            let mut at: Vec<usize> = rows.iter().map(|r| r[pos]).collect();
            at.sort_unstable();
            let per = williams_rows(n) / n;
            let want: Vec<usize> = (0..n).flat_map(|c| std::iter::repeat_n(c, per)).collect();
            assert_eq!(at, want, "n = {n}: position {pos}");
        }
        let mut pairs = vec![0; n * n];
        for r in &rows {
            let mut seen = r.clone();
            seen.sort_unstable();
            assert_eq!(
                seen,
                (0..n).collect::<Vec<_>>(),
                "n = {n}: a row is an order"
            );
            for w in r.windows(2) {
                pairs[w[0] * n + w[1]] += 1;
            }
        }
        let per_pair = if n.is_multiple_of(2) { 1 } else { 2 };
        for a in 0..n {
            for b in 0..n {
                let want = if a == b { 0 } else { per_pair };
                assert_eq!(pairs[a * n + b], want, "n = {n}: {a} then {b}");
            }
        }
    }

    #[test]
    fn williams_squares_balance_positions_and_neighbours() {
        for n in 1..=9 {
            check(n);
        }
        // The textbook four: 0 1 3 2 / 1 2 0 3 / 2 3 1 0 / 3 0 2 1.
        assert_eq!(williams(4, 0), vec![0, 1, 3, 2]);
        assert_eq!(williams(4, 2), vec![2, 3, 1, 0]);
        assert_eq!(williams(4, 4), williams(4, 0));
    }

    #[test]
    fn shuffles_are_orders_and_depend_on_the_seed() {
        let a = shuffled(8, 1);
        let mut s = a.clone();
        s.sort_unstable();
        assert_eq!(s, (0..8).collect::<Vec<_>>());
        assert_eq!(a, shuffled(8, 1));
        assert_ne!(a, shuffled(8, 2));
    }
}
