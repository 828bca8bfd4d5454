//! Faults to inject into the chain, and their one-line text form (the control
//! protocol of the `microrobot-ethercat-emulator` binary).

use std::time::Duration;

/// A fault to inject with [`crate::Emulator::inject`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Fault {
    /// The drive detects a fault: error code into 0x603F, state to Fault reaction
    /// active then Fault (statusword bit 3). Cleared by a fault reset (controlword bit 7
    /// rising edge).
    DriveFault {
        /// Drive position in the chain (0-based).
        drive: usize,
        /// CiA 402 error code for 0x603F (e.g. 0x2310 overcurrent).
        error_code: u16,
    },
    /// The SubDevice drops out of OP to SAFE-OP with the AL status error bit set and
    /// `al_status_code` in 0x0134; its outputs stop counting in the working counter.
    /// The master recovers it with an error acknowledge (AL control bit 4).
    DropOutOfOp {
        /// Drive position in the chain (0-based).
        drive: usize,
        /// AL status code (0x001B sync manager watchdog is usual).
        al_status_code: u16,
    },
    /// The next `count` frames are lost (no answer: the master times out).
    LoseFrames {
        /// Frames to drop.
        count: u32,
    },
    /// The next `count` frames are answered `delay` late.
    DelayFrames {
        /// How late.
        delay: Duration,
        /// Frames to delay.
        count: u32,
    },
    /// The link is down in front of the drive at `position`: it and every drive after
    /// it stop answering. Position 0 silences the whole chain (no frame comes back).
    LinkDown {
        /// First unreachable drive.
        position: usize,
    },
    /// Clears lost, late and link-down faults.
    ClearLink,
    /// The drive reports another identity (SII and 0x1018) from the next discovery on.
    WrongIdentity {
        /// Drive position in the chain (0-based).
        drive: usize,
        /// Vendor id to report.
        vendor_id: u32,
        /// Product code to report.
        product_code: u32,
    },
}

/// A control line that is not a command.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct ParseError(pub String);

fn number<T: TryFrom<u64>>(word: Option<&str>, what: &str) -> Result<T, ParseError> {
    let w = word.ok_or_else(|| ParseError(format!("missing {what}")))?;
    let v = if let Some(hex) = w.strip_prefix("0x").or_else(|| w.strip_prefix("0X")) {
        u64::from_str_radix(hex, 16)
    } else {
        w.parse::<u64>()
    }
    .map_err(|_| ParseError(format!("{what}: \"{w}\" is not a number")))?;
    T::try_from(v).map_err(|_| ParseError(format!("{what}: {w} is out of range")))
}

impl std::str::FromStr for Fault {
    type Err = ParseError;

    /// Parses one command line:
    ///
    /// - `drive-fault DRIVE ERROR_CODE`
    /// - `drop-op DRIVE [AL_STATUS_CODE]` (default 0x001B)
    /// - `lose COUNT`
    /// - `delay MILLISECONDS COUNT`
    /// - `link-down [POSITION]` (default 0)
    /// - `link-up`
    /// - `identity DRIVE VENDOR_ID PRODUCT_CODE`
    ///
    /// Numbers are decimal or 0x-prefixed hexadecimal.
    fn from_str(line: &str) -> Result<Fault, ParseError> {
        let mut w = line.split_whitespace();
        let verb = w.next().ok_or_else(|| ParseError("empty command".into()))?;
        let fault = match verb {
            "drive-fault" => Fault::DriveFault {
                drive: number(w.next(), "drive")?,
                error_code: number(w.next(), "error code")?,
            },
            "drop-op" => Fault::DropOutOfOp {
                drive: number(w.next(), "drive")?,
                al_status_code: match w.next() {
                    Some(c) => number(Some(c), "AL status code")?,
                    None => crate::esc::al_status_code::SM_WATCHDOG,
                },
            },
            "lose" => Fault::LoseFrames {
                count: number(w.next(), "count")?,
            },
            "delay" => Fault::DelayFrames {
                delay: Duration::from_millis(number(w.next(), "milliseconds")?),
                count: number(w.next(), "count")?,
            },
            "link-down" => Fault::LinkDown {
                position: match w.next() {
                    Some(p) => number(Some(p), "position")?,
                    None => 0,
                },
            },
            "link-up" => Fault::ClearLink,
            "identity" => Fault::WrongIdentity {
                drive: number(w.next(), "drive")?,
                vendor_id: number(w.next(), "vendor id")?,
                product_code: number(w.next(), "product code")?,
            },
            other => return Err(ParseError(format!("unknown command \"{other}\""))),
        };
        if let Some(extra) = w.next() {
            return Err(ParseError(format!("unexpected \"{extra}\" after {verb}")));
        }
        Ok(fault)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lines_parse_and_bad_lines_say_why() {
        assert_eq!(
            "drive-fault 2 0x2310".parse(),
            Ok(Fault::DriveFault {
                drive: 2,
                error_code: 0x2310
            })
        );
        assert_eq!(
            "drop-op 1".parse(),
            Ok(Fault::DropOutOfOp {
                drive: 1,
                al_status_code: 0x001B
            })
        );
        assert_eq!(
            "delay 50 3".parse(),
            Ok(Fault::DelayFrames {
                delay: Duration::from_millis(50),
                count: 3
            })
        );
        assert_eq!("link-down".parse(), Ok(Fault::LinkDown { position: 0 }));
        let e = "drive-fault 1 0x1FFFF".parse::<Fault>().expect_err("u16");
        assert!(e.0.contains("out of range"), "{e}");
        assert!("frobnicate".parse::<Fault>().is_err());
        assert!("lose 3 4".parse::<Fault>().is_err());
    }
}
