//! How a `microrobot` command's error becomes its exit code: an error may carry one of
//! [`microrobot_runtime::exit_code`]; any other error exits with `FAILURE`.

use microrobot_runtime::exit_code;

/// An error that exits with `code`.
#[derive(Debug)]
pub struct Coded {
    /// One of [`exit_code`].
    pub code: u8,
    /// What went wrong.
    pub error: anyhow::Error,
}

impl std::fmt::Display for Coded {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{:#}", self.error)
    }
}

impl std::error::Error for Coded {}

/// Tags an error with the exit code it ends the command with (for `map_err`).
pub fn with_code(code: u8) -> impl FnOnce(anyhow::Error) -> anyhow::Error {
    move |error| Coded { code, error }.into()
}

/// The exit code of a command's error: its tag, else `FAILURE`.
pub fn code_of(e: &anyhow::Error) -> u8 {
    e.chain()
        .find_map(|c| c.downcast_ref::<Coded>())
        .map_or(exit_code::FAILURE, |c| c.code)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_tagged_error_keeps_its_code_through_context() {
        let e = with_code(exit_code::JOB_FAILED)(anyhow::anyhow!("refused"));
        let e = e.context("sending");
        assert_eq!(code_of(&e), exit_code::JOB_FAILED);
        assert_eq!(code_of(&anyhow::anyhow!("plain")), exit_code::FAILURE);
    }
}
