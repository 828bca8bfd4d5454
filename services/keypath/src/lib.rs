//! Reading TOML files key by key, for every file format of the stack (the pipeline
//! config, robot files and overlays): a [`Table`] is a table at a key path of a named
//! file; its readers check each value's type, finiteness and range, and [`Table::allow`]
//! refuses the keys a format does not define. Every error is a [`KeyError`] that names
//! the file and the full key path (`watchdog.stale_ms`, `joints[2].limits.min_deg`), so
//! a user finds the typo; nothing is silently defaulted except keys that are absent.
//!
//! Why not `serde`: `#[serde(deny_unknown_fields)]` names neither the file nor the full
//! path, range checks would come after deserialisation without the key, and the formats'
//! defaults depend on other keys (the rate, the joint type).

use toml::Value;

/// What is wrong with a key (see [`KeyError`]).
#[derive(Debug, Clone, PartialEq)]
pub enum Problem {
    /// A required key is absent.
    Missing,
    /// A key the format does not define (often a typo or a wrong unit suffix).
    Unknown {
        /// The keys allowed at that place, comma separated.
        expected: String,
    },
    /// A value of the wrong TOML type or shape.
    WrongType {
        /// What was expected (`a number`, `true or false`, ...).
        expected: &'static str,
    },
    /// NaN or infinity.
    NonFinite(f64),
    /// Out of range, inconsistent with another key, or otherwise invalid.
    Invalid(String),
}

impl std::fmt::Display for Problem {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Missing => write!(f, "missing required key"),
            Self::Unknown { expected } => write!(f, "unknown key (expected one of: {expected})"),
            Self::WrongType { expected } => write!(f, "expected {expected}"),
            Self::NonFinite(v) => write!(f, "{v} is not a finite number"),
            Self::Invalid(message) => write!(f, "{message}"),
        }
    }
}

/// A refused key: `{file}: {key}: {problem}`.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{file}: {key}: {problem}")]
pub struct KeyError {
    /// File name (or other origin) of the TOML text.
    pub file: String,
    /// Full key path.
    pub key: String,
    /// What is wrong.
    pub problem: Problem,
}

/// `path.key`, or `key` at the root.
pub fn join(path: &str, key: &str) -> String {
    if path.is_empty() {
        key.to_string()
    } else {
        format!("{path}.{key}")
    }
}

/// An interval a number must lie in: `[lo, hi]`, or `(lo, hi]` when `lo_open`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Range {
    /// Lower end.
    pub lo: f64,
    /// Upper end (always included).
    pub hi: f64,
    /// The lower end itself is excluded.
    pub lo_open: bool,
}

impl Range {
    /// `[lo, hi]`.
    pub const fn closed(lo: f64, hi: f64) -> Self {
        Self {
            lo,
            hi,
            lo_open: false,
        }
    }

    /// `(lo, hi]`.
    pub const fn left_open(lo: f64, hi: f64) -> Self {
        Self {
            lo,
            hi,
            lo_open: true,
        }
    }

    /// `v` lies in the interval.
    pub fn contains(&self, v: f64) -> bool {
        let above_lo = if self.lo_open {
            v > self.lo
        } else {
            v >= self.lo
        };
        above_lo && v <= self.hi
    }
}

impl std::fmt::Display for Range {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let open = if self.lo_open { "(" } else { "[" };
        write!(f, "{open}{}, {}]", self.lo, self.hi)
    }
}

/// A table at a key path of a file (absent tables read as empty: every key absent).
#[derive(Debug, Clone)]
pub struct Table<'t> {
    file: &'t str,
    path: String,
    table: Option<&'t toml::Table>,
}

impl<'t> Table<'t> {
    /// The document's root table of file `file`.
    pub fn root(file: &'t str, table: &'t toml::Table) -> Self {
        Self {
            file,
            path: String::new(),
            table: Some(table),
        }
    }

    /// The key path of this table (empty at the root).
    pub fn path(&self) -> &str {
        &self.path
    }

    /// The file name errors carry.
    pub fn file(&self) -> &'t str {
        self.file
    }

    /// The full key path of `key` in this table.
    pub fn key(&self, key: &str) -> String {
        join(&self.path, key)
    }

    /// The table's TOML, `None` when it is absent.
    pub fn raw(&self) -> Option<&'t toml::Table> {
        self.table
    }

    /// The raw value of `key`, if present.
    pub fn get(&self, key: &str) -> Option<&'t Value> {
        self.table.and_then(|t| t.get(key))
    }

    /// An error about `key` (a key of this table, or `""` for the table itself).
    pub fn error(&self, key: &str, problem: Problem) -> KeyError {
        KeyError {
            file: self.file.to_string(),
            key: if key.is_empty() {
                self.path.clone()
            } else {
                self.key(key)
            },
            problem,
        }
    }

    /// An [`Problem::Invalid`] error about `key` with `message`.
    pub fn invalid(&self, key: &str, message: impl Into<String>) -> KeyError {
        self.error(key, Problem::Invalid(message.into()))
    }

    /// Refuses any key not in `allowed` (the first, in the file's key order).
    pub fn allow(&self, allowed: &[&str]) -> Result<(), KeyError> {
        let Some(t) = self.table else {
            return Ok(());
        };
        match t.keys().find(|k| !allowed.contains(&k.as_str())) {
            Some(k) => Err(self.error(
                k,
                Problem::Unknown {
                    expected: allowed.join(", "),
                },
            )),
            None => Ok(()),
        }
    }

    /// The table at `key`, which must be present.
    pub fn table(&self, key: &str) -> Result<Table<'t>, KeyError> {
        match self.opt_table(key)? {
            t if t.table.is_some() => Ok(t),
            _ => Err(self.error(key, Problem::Missing)),
        }
    }

    /// The table at `key`; absent, an empty one (every key absent).
    pub fn opt_table(&self, key: &str) -> Result<Table<'t>, KeyError> {
        let table = match self.get(key) {
            None => None,
            Some(Value::Table(t)) => Some(t),
            Some(_) => return Err(self.wrong(key, "a table")),
        };
        Ok(Table {
            file: self.file,
            path: self.key(key),
            table,
        })
    }

    /// The table at `key` (absent: empty), refusing any key not in `allowed`: one
    /// section of a format.
    pub fn section(&self, key: &str, allowed: &[&str]) -> Result<Table<'t>, KeyError> {
        let t = self.opt_table(key)?;
        t.allow(allowed)?;
        Ok(t)
    }

    /// A table that is an element of an array (`joints[2]`), read with this file.
    pub fn element(&self, path: String, table: &'t toml::Table) -> Table<'t> {
        Table {
            file: self.file,
            path,
            table: Some(table),
        }
    }

    fn wrong(&self, key: &str, expected: &'static str) -> KeyError {
        self.error(key, Problem::WrongType { expected })
    }

    /// `v` as a finite number; errors are about the full key path `key_path`.
    pub fn number_of(&self, v: &Value, key_path: String) -> Result<f64, KeyError> {
        let error = |problem| KeyError {
            file: self.file.to_string(),
            key: key_path.clone(),
            problem,
        };
        let x = match v {
            Value::Float(x) => *x,
            Value::Integer(i) => *i as f64,
            _ => {
                return Err(error(Problem::WrongType {
                    expected: "a number",
                }));
            }
        };
        if !x.is_finite() {
            return Err(error(Problem::NonFinite(x)));
        }
        Ok(x)
    }

    /// The finite number at `key`; `None` when absent.
    pub fn opt_number(&self, key: &str) -> Result<Option<f64>, KeyError> {
        self.get(key)
            .map(|v| self.number_of(v, self.key(key)))
            .transpose()
    }

    /// The finite number at `key`, which must be present.
    pub fn number(&self, key: &str) -> Result<f64, KeyError> {
        self.opt_number(key)?
            .ok_or_else(|| self.error(key, Problem::Missing))
    }

    /// The number at `key` within `range`; `None` when absent.
    pub fn opt_number_in(&self, key: &str, range: Range) -> Result<Option<f64>, KeyError> {
        match self.opt_number(key)? {
            Some(v) if !range.contains(v) => {
                Err(self.invalid(key, format!("{v} is out of range {range}")))
            }
            v => Ok(v),
        }
    }

    /// The number at `key` within `range`, `default` when absent.
    pub fn number_in(&self, key: &str, default: f64, range: Range) -> Result<f64, KeyError> {
        Ok(self.opt_number_in(key, range)?.unwrap_or(default))
    }

    /// The integer at `key` within `[lo, hi]`, `default` when absent.
    pub fn integer_in(&self, key: &str, default: u64, lo: u64, hi: u64) -> Result<u64, KeyError> {
        match self.get(key) {
            None => Ok(default),
            Some(Value::Integer(i)) => match u64::try_from(*i) {
                Ok(v) if (lo..=hi).contains(&v) => Ok(v),
                _ => Err(self.invalid(key, format!("{i} is out of range [{lo}, {hi}]"))),
            },
            Some(_) => Err(self.wrong(key, "an integer")),
        }
    }

    /// The boolean at `key`, `default` when absent.
    pub fn bool_or(&self, key: &str, default: bool) -> Result<bool, KeyError> {
        match self.get(key) {
            None => Ok(default),
            Some(Value::Boolean(b)) => Ok(*b),
            Some(_) => Err(self.wrong(key, "true or false")),
        }
    }

    /// The string at `key`; `None` when absent.
    pub fn opt_string(&self, key: &str) -> Result<Option<&'t str>, KeyError> {
        match self.get(key) {
            None => Ok(None),
            Some(Value::String(s)) => Ok(Some(s)),
            Some(_) => Err(self.wrong(key, "a string")),
        }
    }

    /// The string at `key`, which must be present.
    pub fn string(&self, key: &str) -> Result<&'t str, KeyError> {
        self.opt_string(key)?
            .ok_or_else(|| self.error(key, Problem::Missing))
    }

    /// The option named by the string at `key`, `default` when absent.
    pub fn choice<T: Copy>(
        &self,
        key: &str,
        default: T,
        options: &[(&str, T)],
    ) -> Result<T, KeyError> {
        let Some(s) = self.opt_string(key)? else {
            return Ok(default);
        };
        options
            .iter()
            .find(|(name, _)| *name == s)
            .map(|(_, v)| *v)
            .ok_or_else(|| {
                let names: Vec<&str> = options.iter().map(|(n, _)| *n).collect();
                self.invalid(key, format!("`{s}` is not one of: {}", names.join(", ")))
            })
    }

    /// The array at `key`; `None` when absent.
    pub fn opt_array(&self, key: &str) -> Result<Option<&'t Vec<Value>>, KeyError> {
        match self.get(key) {
            None => Ok(None),
            Some(Value::Array(a)) => Ok(Some(a)),
            Some(_) => Err(self.wrong(key, "an array")),
        }
    }

    /// An error of the wrong type at `key`, with what was expected.
    pub fn wrong_type(&self, key: &str, expected: &'static str) -> KeyError {
        self.wrong(key, expected)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn doc(text: &str) -> toml::Table {
        text.parse().expect("valid TOML")
    }

    #[test]
    fn errors_name_the_file_and_the_full_key_path() {
        let t = doc("[watchdog]\nstale_ms = \"soon\"\nfault_ms = nan\ntypo = 1\n[a.b]\nc = 2\n");
        let root = Table::root("p.toml", &t);
        let w = root.opt_table("watchdog").expect("table");
        assert_eq!(
            w.number("stale_ms").unwrap_err().to_string(),
            "p.toml: watchdog.stale_ms: expected a number"
        );
        assert_eq!(
            w.number("fault_ms").unwrap_err().to_string(),
            "p.toml: watchdog.fault_ms: NaN is not a finite number"
        );
        assert_eq!(
            w.allow(&["stale_ms", "fault_ms"]).unwrap_err().to_string(),
            "p.toml: watchdog.typo: unknown key (expected one of: stale_ms, fault_ms)"
        );
        let b = root.table("a").and_then(|a| a.table("b")).expect("a.b");
        assert_eq!(b.number("c"), Ok(2.0));
        assert_eq!(
            b.number("d").unwrap_err().to_string(),
            "p.toml: a.b.d: missing required key"
        );
        assert_eq!(
            root.table("nope").unwrap_err().to_string(),
            "p.toml: nope: missing required key"
        );
    }

    #[test]
    fn absent_keys_default_and_present_ones_are_checked() {
        let t = doc("x = 0.0\nn = -1\nb = 1\nmode = \"fast\"\n");
        let root = Table::root("f", &t);
        assert_eq!(root.number_in("y", 5.0, Range::closed(0.0, 10.0)), Ok(5.0));
        assert_eq!(root.number_in("x", 5.0, Range::closed(0.0, 10.0)), Ok(0.0));
        assert_eq!(
            root.number_in("x", 5.0, Range::left_open(0.0, 10.0))
                .unwrap_err()
                .to_string(),
            "f: x: 0 is out of range (0, 10]"
        );
        assert_eq!(
            root.integer_in("n", 1, 0, 9).unwrap_err().to_string(),
            "f: n: -1 is out of range [0, 9]"
        );
        assert_eq!(
            root.bool_or("b", true).unwrap_err().to_string(),
            "f: b: expected true or false"
        );
        assert_eq!(
            root.choice("mode", 1, &[("slow", 1), ("medium", 2)])
                .unwrap_err()
                .to_string(),
            "f: mode: `fast` is not one of: slow, medium"
        );
        assert_eq!(root.choice("other", 1, &[("slow", 1)]), Ok(1));
        let empty = root.opt_table("absent").expect("absent table");
        assert!(empty.raw().is_none());
        assert_eq!(empty.path(), "absent");
        assert_eq!(empty.bool_or("k", true), Ok(true));
    }
}
