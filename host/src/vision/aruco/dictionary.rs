//! The ArUco dictionaries (bit tables in `dictionaries.rs`, generated from OpenCV by
//! tools/aruco_dictionaries.py) and the look-up of a read bit grid in any of its four
//! rotations.

use std::fmt;
use std::str::FromStr;

use super::dictionaries as tables;

/// A predefined ArUco dictionary (OpenCV's names).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Dictionary {
    /// `DICT_4X4_50`.
    Dict4x4_50,
    /// `DICT_6X6_250`.
    Dict6x6_250,
    /// `DICT_ARUCO_ORIGINAL` (5x5 bits, 1024 markers).
    ArucoOriginal,
}

/// A dictionary name that is not one of [`Dictionary::ALL`].
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
#[error("unknown ArUco dictionary '{0}' (known: DICT_4X4_50, DICT_6X6_250, DICT_ARUCO_ORIGINAL)")]
pub struct UnknownDictionary(pub String);

impl Dictionary {
    /// Every dictionary implemented.
    pub const ALL: [Dictionary; 3] = [
        Dictionary::Dict4x4_50,
        Dictionary::Dict6x6_250,
        Dictionary::ArucoOriginal,
    ];

    /// OpenCV's name, e.g. `DICT_6X6_250`.
    pub fn name(self) -> &'static str {
        match self {
            Dictionary::Dict4x4_50 => "DICT_4X4_50",
            Dictionary::Dict6x6_250 => "DICT_6X6_250",
            Dictionary::ArucoOriginal => "DICT_ARUCO_ORIGINAL",
        }
    }

    /// The codes: inner bits (black 0, white 1) in rotation 0, row-major from the top-left,
    /// first bit most significant.
    pub fn codes(self) -> &'static [u64] {
        match self {
            Dictionary::Dict4x4_50 => &tables::DICT_4X4_50,
            Dictionary::Dict6x6_250 => &tables::DICT_6X6_250,
            Dictionary::ArucoOriginal => &tables::DICT_ARUCO_ORIGINAL,
        }
    }

    /// Inner bits per side.
    pub fn bits(self) -> usize {
        self.size_and_correction().0
    }

    /// OpenCV's `maxCorrectionBits` of the dictionary.
    pub fn max_correction_bits(self) -> usize {
        self.size_and_correction().1
    }

    fn size_and_correction(self) -> (usize, usize) {
        match self {
            Dictionary::Dict4x4_50 => tables::DICT_4X4_50_SIZE,
            Dictionary::Dict6x6_250 => tables::DICT_6X6_250_SIZE,
            Dictionary::ArucoOriginal => tables::DICT_ARUCO_ORIGINAL_SIZE,
        }
    }

    /// Finds a read code: `(id, k, hamming distance)` of the closest marker, where the read
    /// grid equals the marker's code turned `k` quarter turns clockwise, when the distance
    /// is at most `max_errors`.
    pub fn identify(self, read: u64, max_errors: usize) -> Option<(usize, usize, usize)> {
        identify_in(self.codes(), self.bits(), read, max_errors)
    }
}

impl fmt::Display for Dictionary {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Dictionary {
    type Err = UnknownDictionary;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Dictionary::ALL
            .into_iter()
            .find(|d| d.name().eq_ignore_ascii_case(s.trim()))
            .ok_or_else(|| UnknownDictionary(s.to_string()))
    }
}

/// [`Dictionary::identify`] in any table of `n x n` codes (the AprilGrid's tag36h11 too).
pub fn identify_in(
    codes: &[u64],
    n: usize,
    read: u64,
    max_errors: usize,
) -> Option<(usize, usize, usize)> {
    let mut rotated = [read; 4];
    // rotated[k]: the read grid turned k quarter turns anticlockwise, i.e. the marker in
    // rotation 0 when it appears turned k clockwise.
    for k in 1..4 {
        rotated[k] = rotate_ccw(rotated[k - 1], n);
    }
    let mut best: Option<(usize, usize, usize)> = None;
    for (id, &code) in codes.iter().enumerate() {
        for (k, &r) in rotated.iter().enumerate() {
            let d = (code ^ r).count_ones() as usize;
            if d <= max_errors && best.is_none_or(|b| d < b.2) {
                best = Some((id, k, d));
            }
        }
    }
    best
}

/// Bit `(r, c)` of an `n x n` code.
pub fn bit(code: u64, n: usize, r: usize, c: usize) -> bool {
    (code >> (n * n - 1 - (r * n + c))) & 1 == 1
}

/// An `n x n` code from a row-major bit grid.
pub fn code_of(bits: &[bool]) -> u64 {
    bits.iter().fold(0, |acc, &b| (acc << 1) | u64::from(b))
}

/// The code turned a quarter turn clockwise on screen: `new(r, c) = old(n-1-c, r)`.
pub fn rotate_cw(code: u64, n: usize) -> u64 {
    let bits: Vec<bool> = (0..n * n)
        .map(|i| bit(code, n, n - 1 - i % n, i / n))
        .collect();
    code_of(&bits)
}

/// The code turned a quarter turn anticlockwise on screen: `new(r, c) = old(c, n-1-r)`.
pub fn rotate_ccw(code: u64, n: usize) -> u64 {
    let bits: Vec<bool> = (0..n * n)
        .map(|i| bit(code, n, i % n, n - 1 - i / n))
        .collect();
    code_of(&bits)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Codes as printed by OpenCV 5.0 (`cv2.aruco.Dictionary.getBitsFromByteList` of
    /// `getPredefinedDictionary(...).bytesList[id]`), typed in by hand from its output.
    #[test]
    fn known_codes_match_opencv() {
        let grid =
            |rows: &[&str]| code_of(&rows.concat().chars().map(|c| c == '1').collect::<Vec<_>>());
        assert_eq!(
            Dictionary::Dict4x4_50.codes()[0],
            grid(&["1011", "0101", "0011", "0010"])
        );
        assert_eq!(
            Dictionary::Dict4x4_50.codes()[49],
            grid(&["0101", "0000", "0001", "0011"])
        );
        let six = ["000111", "100011", "110111", "011000", "001010", "100110"];
        assert_eq!(Dictionary::Dict6x6_250.codes()[0], grid(&six));
        let six = ["011100", "000011", "110100", "111000", "101001", "100000"];
        assert_eq!(Dictionary::Dict6x6_250.codes()[249], grid(&six));
        let five = ["10000"; 5];
        assert_eq!(Dictionary::ArucoOriginal.codes()[0], grid(&five));
        let five = ["01110"; 5];
        assert_eq!(Dictionary::ArucoOriginal.codes()[1023], grid(&five));
        assert_eq!(Dictionary::Dict4x4_50.codes().len(), 50);
        assert_eq!(Dictionary::Dict6x6_250.codes().len(), 250);
        assert_eq!(Dictionary::ArucoOriginal.codes().len(), 1024);
        assert_eq!(
            (
                Dictionary::Dict6x6_250.bits(),
                Dictionary::Dict6x6_250.max_correction_bits()
            ),
            (6, 5)
        );
        assert_eq!(Dictionary::ArucoOriginal.bits(), 5);
    }

    #[test]
    fn rotations_are_inverse_and_identify_finds_the_turn() {
        for dict in Dictionary::ALL {
            let n = dict.bits();
            let code = dict.codes()[7];
            assert_eq!(rotate_ccw(rotate_cw(code, n), n), code);
            let turned = rotate_cw(rotate_cw(code, n), n);
            assert_eq!(dict.identify(turned, 0), Some((7, 2, 0)));
            let one_off = rotate_cw(code, n) ^ 1;
            let found = dict.identify(one_off, 1).map(|(id, k, _)| (id, k));
            assert_eq!(found, Some((7, 1)));
        }
    }

    #[test]
    fn parses_opencv_names() {
        assert_eq!("DICT_6X6_250".parse(), Ok(Dictionary::Dict6x6_250));
        assert_eq!("dict_aruco_original".parse(), Ok(Dictionary::ArucoOriginal));
        assert!("DICT_7X7_50".parse::<Dictionary>().is_err());
    }
}
