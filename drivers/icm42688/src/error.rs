//! Typed errors of the driver, generic over the SPI device's error.

use core::fmt;

/// An error of the driver. Nothing read from the bus makes the driver panic: every
/// unexpected value is one of these, or a field of [`crate::FifoRead`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Error<E> {
    /// The SPI device failed.
    Spi(E),
    /// `WHO_AM_I` did not read 0x47: another part, no part, or a broken bus.
    WrongDevice {
        /// The value read.
        found: u8,
    },
    /// `INT_STATUS.RESET_DONE_INT` was not set after the soft reset and its 1 ms wait.
    ResetNotDone {
        /// `INT_STATUS` as read.
        int_status: u8,
    },
    /// A configuration value does not fit its register ([`crate::AntiAlias::is_valid`]).
    InvalidConfig,
    /// [`crate::Icm42688::read_fifo`] before [`crate::Icm42688::init`].
    NotInitialized,
    /// The self-test got fewer than half of its samples valid (the sensor never produced
    /// data: off, or stuck at the invalid marker -32768).
    SelfTestNoData,
}

impl<E> From<E> for Error<E> {
    fn from(e: E) -> Self {
        Error::Spi(e)
    }
}

impl<E: fmt::Debug> fmt::Display for Error<E> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Error::Spi(e) => write!(f, "SPI error: {e:?}"),
            Error::WrongDevice { found } => {
                write!(f, "WHO_AM_I read {found:#04x}, expected 0x47 (ICM-42688-P)")
            }
            Error::ResetNotDone { int_status } => write!(
                f,
                "soft reset not done: INT_STATUS {int_status:#04x} lacks RESET_DONE_INT"
            ),
            Error::InvalidConfig => write!(f, "configuration value out of its register's range"),
            Error::NotInitialized => write!(f, "driver not initialised"),
            Error::SelfTestNoData => write!(f, "self-test: the sensor produced no valid data"),
        }
    }
}

impl<E: fmt::Debug> core::error::Error for Error<E> {}
