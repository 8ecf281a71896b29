//! Names a message offers when a file names something that is not there: the model's own
//! names nearest the one written (by edit distance), so a typo shows its fix.

/// At most this many names are offered.
const OFFERED: usize = 6;

/// `"; did you mean `a`, `b`?"`-style text: the names of `candidates` nearest `name`, or all
/// of them when there are few. Empty when there are none.
pub fn nearest(name: &str, candidates: &[&str]) -> String {
    if candidates.is_empty() {
        return String::new();
    }
    let mut ranked: Vec<(usize, &str)> = candidates
        .iter()
        .map(|c| (edit_distance(&name.to_lowercase(), &c.to_lowercase()), *c))
        .collect();
    ranked.sort();
    let shown: Vec<String> = ranked
        .iter()
        .take(OFFERED)
        .map(|(_, c)| format!("`{c}`"))
        .collect();
    if candidates.len() <= OFFERED {
        format!("; the names are {}", shown.join(", "))
    } else {
        format!(
            "; the nearest of its {} names are {}",
            candidates.len(),
            shown.join(", ")
        )
    }
}

/// Levenshtein distance over characters (one row of the table at a time).
fn edit_distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut row: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut diagonal = row[0];
        row[0] = i + 1;
        for (j, cb) in b.iter().enumerate() {
            let substitute = diagonal + usize::from(ca != *cb);
            diagonal = row[j + 1];
            row[j + 1] = substitute.min(row[j] + 1).min(diagonal + 1);
        }
    }
    row[b.len()]
}

#[cfg(test)]
mod tests {
    use super::{edit_distance, nearest};

    #[test]
    fn distances_count_edits() {
        assert_eq!(edit_distance("", ""), 0);
        assert_eq!(edit_distance("hand", "hand"), 0);
        assert_eq!(edit_distance("hnad", "hand"), 2);
        assert_eq!(edit_distance("hat", "hand"), 2);
        assert_eq!(edit_distance("kitten", "sitting"), 3);
    }

    #[test]
    fn a_typo_is_offered_its_fix_first() {
        let few = ["pole", "cart", "world"];
        assert_eq!(
            nearest("pol", &few),
            "; the names are `pole`, `world`, `cart`"
        );
        let many = ["a1", "a2", "a3", "a4", "a5", "a6", "tool0", "wrist_3_link"];
        let text = nearest("tool", &many);
        assert!(
            text.starts_with("; the nearest of its 8 names are `tool0`"),
            "{text}"
        );
        assert_eq!(nearest("x", &[]), "");
    }
}
