//! The site ice classes of IEA Wind Task 19 (Wind Energy in Cold Climates):
//! a site's class by the share of the year with meteorological icing, with
//! the instrumental icing and production loss typical of each class.
//!
//! Source: IEA Wind TCP Task 19, "Available Technologies of Wind Energy in
//! Cold Climates" (2nd ed., 2018) and the Recommended Practice 13 "Wind
//! Energy Projects in Cold Climates"; the same table is reproduced by the
//! Icing Wiki of the Icing Centre ("Ice classes", IEA Wind's ice
//! classification system). The class follows from meteorological icing; the
//! instrumental ranges overlap between classes and are given as a check.

/// One IEA ice class.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct IceClass {
    /// The class, 1–5.
    pub class: u8,
    /// Meteorological icing, % of the year: from (inclusive).
    pub met_from_pct: f64,
    /// … to (exclusive; `f64::INFINITY` for class 5).
    pub met_to_pct: f64,
    /// Instrumental icing, % of the year: from.
    pub instr_from_pct: f64,
    /// … to.
    pub instr_to_pct: f64,
    /// Production loss, % of the annual production, as text.
    pub production_loss: &'static str,
}

/// The table, class 1 to 5.
pub const IEA_ICE_CLASSES: [IceClass; 5] = [
    IceClass {
        class: 1,
        met_from_pct: 0.0,
        met_to_pct: 0.5,
        instr_from_pct: 0.0,
        instr_to_pct: 1.5,
        production_loss: "0–0.5",
    },
    IceClass {
        class: 2,
        met_from_pct: 0.5,
        met_to_pct: 3.0,
        instr_from_pct: 1.0,
        instr_to_pct: 9.0,
        production_loss: "0.5–5",
    },
    IceClass {
        class: 3,
        met_from_pct: 3.0,
        met_to_pct: 5.0,
        instr_from_pct: 6.0,
        instr_to_pct: 15.0,
        production_loss: "3–12",
    },
    IceClass {
        class: 4,
        met_from_pct: 5.0,
        met_to_pct: 10.0,
        instr_from_pct: 10.0,
        instr_to_pct: 30.0,
        production_loss: "10–25",
    },
    IceClass {
        class: 5,
        met_from_pct: 10.0,
        met_to_pct: f64::INFINITY,
        instr_from_pct: 20.0,
        instr_to_pct: f64::INFINITY,
        production_loss: "> 20",
    },
];

/// The class of a meteorological-icing share, % (class 1 below 0.5 %, …,
/// class 5 from 10 %).
pub fn class_of_meteorological(share_pct: f64) -> &'static IceClass {
    IEA_ICE_CLASSES
        .iter()
        .find(|c| share_pct < c.met_to_pct)
        .unwrap_or(&IEA_ICE_CLASSES[4])
}

/// The classes whose instrumental range holds a share, % (the ranges
/// overlap: one or two classes).
pub fn classes_of_instrumental(share_pct: f64) -> Vec<u8> {
    IEA_ICE_CLASSES
        .iter()
        .filter(|c| share_pct >= c.instr_from_pct && share_pct < c.instr_to_pct)
        .map(|c| c.class)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn classes_follow_the_table() {
        let class = |p: f64| class_of_meteorological(p).class;
        assert_eq!(class(0.0), 1);
        assert_eq!(class(0.49), 1);
        assert_eq!(class(0.5), 2);
        assert_eq!(class(2.99), 2);
        assert_eq!(class(3.0), 3);
        assert_eq!(class(7.5), 4);
        assert_eq!(class(10.0), 5);
        assert_eq!(class(60.0), 5);
        assert_eq!(classes_of_instrumental(1.2), [1, 2]);
        assert_eq!(classes_of_instrumental(4.0), [2]);
        assert_eq!(classes_of_instrumental(12.0), [3, 4]);
        assert_eq!(classes_of_instrumental(40.0), [5]);
    }
}
