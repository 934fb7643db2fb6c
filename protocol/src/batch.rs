//! [`Bounded`]: a vector of at most `N` items on the stack that serialises as a postcard
//! sequence (a varint length, then the items), so a short batch costs only its items. A
//! sequence longer than `N` fails to decode instead of growing a buffer.

use core::fmt;
use core::marker::PhantomData;

use postcard::experimental::max_size::MaxSize;
use serde::de::{Deserialize, Deserializer, Error as _, SeqAccess, Visitor};
use serde::ser::{Serialize, SerializeSeq, Serializer};

/// At most `N` (< 128, so the length is one byte) items of `T`.
#[derive(Clone, Copy, PartialEq)]
pub struct Bounded<T: Copy + Default, const N: usize> {
    items: [T; N],
    len: u8,
}

impl<T: Copy + Default, const N: usize> Bounded<T, N> {
    const LEN_FITS_ONE_BYTE: () = assert!(N < 128, "Bounded: N must be < 128");

    /// An empty vector.
    pub fn new() -> Self {
        let () = Self::LEN_FITS_ONE_BYTE;
        Self {
            items: [T::default(); N],
            len: 0,
        }
    }

    /// Appends `item`; gives it back when full.
    pub fn push(&mut self, item: T) -> Result<(), T> {
        let slot = self.items.get_mut(usize::from(self.len)).ok_or(item)?;
        *slot = item;
        self.len += 1;
        Ok(())
    }

    /// The items.
    pub fn as_slice(&self) -> &[T] {
        &self.items[..usize::from(self.len)]
    }

    /// Number of items.
    pub fn len(&self) -> usize {
        usize::from(self.len)
    }

    /// True when empty.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// True when it holds `N` items.
    pub fn is_full(&self) -> bool {
        self.len() == N
    }
}

impl<T: Copy + Default, const N: usize> Default for Bounded<T, N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<T: Copy + Default + fmt::Debug, const N: usize> fmt::Debug for Bounded<T, N> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_list().entries(self.as_slice()).finish()
    }
}

impl<T: Copy + Default, const N: usize> FromIterator<T> for Bounded<T, N> {
    /// Collects at most `N` items; the rest are ignored.
    fn from_iter<I: IntoIterator<Item = T>>(iter: I) -> Self {
        let mut b = Self::new();
        for item in iter.into_iter().take(N) {
            let _ = b.push(item);
        }
        b
    }
}

impl<T: Copy + Default + Serialize, const N: usize> Serialize for Bounded<T, N> {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let mut seq = serializer.serialize_seq(Some(self.len()))?;
        for item in self.as_slice() {
            seq.serialize_element(item)?;
        }
        seq.end()
    }
}

struct BoundedVisitor<T, const N: usize>(PhantomData<T>);

impl<'de, T: Copy + Default + Deserialize<'de>, const N: usize> Visitor<'de>
    for BoundedVisitor<T, N>
{
    type Value = Bounded<T, N>;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "a sequence of at most {N} items")
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Self::Value, A::Error> {
        if seq.size_hint().is_some_and(|n| n > N) {
            return Err(A::Error::invalid_length(N + 1, &self));
        }
        let mut out = Bounded::new();
        while let Some(item) = seq.next_element()? {
            out.push(item)
                .map_err(|_| A::Error::invalid_length(N + 1, &self))?;
        }
        Ok(out)
    }
}

impl<'de, T: Copy + Default + Deserialize<'de>, const N: usize> Deserialize<'de> for Bounded<T, N> {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        deserializer.deserialize_seq(BoundedVisitor::<T, N>(PhantomData))
    }
}

impl<T: Copy + Default + MaxSize, const N: usize> MaxSize for Bounded<T, N> {
    const POSTCARD_MAX_SIZE: usize = 1 + N * T::POSTCARD_MAX_SIZE;
}
