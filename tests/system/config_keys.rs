//! Every key of the shipped pipeline, robot and program files, mutated one at a time
//! into each bad class — wrong type, non-finite, unknown key next to it, wrong units
//! (the key renamed to another unit) — must be refused with an error that names the file
//! and the key. Table-driven over the files themselves, so a key added later is covered
//! without a new test. (Out-of-range values are key-specific: the loaders' own tests.)

use std::path::{Path, PathBuf};

use microrobot_model::Robot;
use microrobot_trajectory::program::Program;
use toml::{Table, Value};

fn config_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("config")
}

/// One step of a path into a TOML document.
#[derive(Debug, Clone)]
enum Step {
    Key(String),
    Index(usize),
}

type KeyPath = Vec<Step>;

fn show(p: &KeyPath) -> String {
    let mut s = String::new();
    for st in p {
        match st {
            Step::Key(k) if s.is_empty() => s.push_str(k),
            Step::Key(k) => {
                s.push('.');
                s.push_str(k);
            }
            Step::Index(i) => s.push_str(&format!("[{i}]")),
        }
    }
    s
}

/// Every leaf (a scalar, or an array of scalars) of `v`; arrays of tables are entered
/// at their first element only (the others have the same keys).
fn leaves(v: &Value, path: KeyPath, out: &mut Vec<KeyPath>) {
    match v {
        Value::Table(t) => {
            for (k, x) in t {
                let mut p = path.clone();
                p.push(Step::Key(k.clone()));
                leaves(x, p, out);
            }
        }
        Value::Array(a) if a.first().is_some_and(Value::is_table) => {
            let mut p = path.clone();
            p.push(Step::Index(0));
            leaves(&a[0], p, out);
        }
        _ => out.push(path),
    }
}

fn get_mut<'a>(root: &'a mut Value, path: &[Step]) -> &'a mut Value {
    let mut v = root;
    for st in path {
        v = match st {
            Step::Key(k) => v.as_table_mut().expect("table").get_mut(k).expect("key"),
            Step::Index(i) => &mut v.as_array_mut().expect("array")[*i],
        };
    }
    v
}

/// The parent table of `path` and the leaf key.
fn parent_mut<'a>(root: &'a mut Value, path: &[Step]) -> (&'a mut Table, String) {
    let (last, head) = path.split_last().expect("non-empty path");
    let Step::Key(k) = last else {
        panic!("a leaf is a key")
    };
    (
        get_mut(root, head).as_table_mut().expect("parent table"),
        k.clone(),
    )
}

/// Keys in another unit that a file format accepts on purpose (programs take a joint
/// target as `q_deg` or `q_rad`: config/programs/README.md).
const DOCUMENTED_ALTERNATIVES: [&str; 1] = ["q_rad"];

/// The same key in another unit, if it has a unit suffix.
fn other_unit(key: &str) -> Option<String> {
    const SWAPS: [(&str, &str); 12] = [
        ("_deg_s3", "_rad_s3"),
        ("_deg_s2", "_rad_s2"),
        ("_deg_s", "_rad_s"),
        ("_deg", "_rad"),
        ("_mm_s", "_m_s"),
        ("_kgmm2", "_kgm2"),
        ("_mm", "_m"),
        ("_ms", "_s"),
        ("_hz", "_khz"),
        ("_kg", "_g"),
        ("_nm", "_nmm"),
        ("_us", "_ns"),
    ];
    SWAPS
        .iter()
        .find(|(from, _)| key.ends_with(from))
        .map(|(from, to)| format!("{}{to}", &key[..key.len() - from.len()]))
}

/// The bad variants of the document for the leaf at `path`: (class, key the error must
/// name, document).
fn mutations(doc: &Value, path: &KeyPath) -> Vec<(&'static str, String, Value)> {
    let mut out = Vec::new();
    let leaf = {
        let mut d = doc.clone();
        get_mut(&mut d, path).clone()
    };
    let key = match path.last() {
        Some(Step::Key(k)) => k.clone(),
        _ => return out,
    };
    // Wrong type.
    let wrong = match &leaf {
        Value::String(_) => Value::Integer(7),
        Value::Array(a) if a.first().is_some_and(Value::is_str) => Value::Integer(7),
        _ => Value::String("x".into()),
    };
    let mut d = doc.clone();
    *get_mut(&mut d, path) = wrong;
    out.push(("wrong type", key.clone(), d));
    // Non-finite, for numbers (and the first element of a numeric array).
    for bad in [f64::NAN, f64::INFINITY] {
        let mut d = doc.clone();
        let v = get_mut(&mut d, path);
        let hit = match v {
            Value::Float(_) => {
                *v = Value::Float(bad);
                true
            }
            Value::Array(a) => match a.first_mut() {
                Some(x @ Value::Float(_)) | Some(x @ Value::Integer(_)) => {
                    *x = Value::Float(bad);
                    true
                }
                Some(Value::Array(inner)) if inner.first().is_some_and(Value::is_float) => {
                    inner[0] = Value::Float(bad);
                    true
                }
                _ => false,
            },
            _ => false,
        };
        if hit {
            out.push(("non-finite", key.clone(), d));
        }
    }
    // Unknown key beside it.
    let mut d = doc.clone();
    let (t, _) = parent_mut(&mut d, path);
    let unknown = format!("{key}_bogus");
    t.insert(unknown.clone(), leaf.clone());
    out.push(("unknown key", unknown, d));
    // Wrong units: the key renamed to another unit (unless that unit is a documented
    // alternative spelling, which the loader converts).
    if let Some(renamed) =
        other_unit(&key).filter(|r| !DOCUMENTED_ALTERNATIVES.contains(&r.as_str()))
    {
        let mut d = doc.clone();
        let (t, k) = parent_mut(&mut d, path);
        let v = t.remove(&k).expect("leaf");
        t.insert(renamed.clone(), v);
        out.push(("wrong units", renamed, d));
    }
    out
}

/// Runs every mutation of `file` through `load`; returns the failures.
fn check_every_key(file: &str, load: impl Fn(&str) -> Result<(), String>) -> (usize, Vec<String>) {
    let text = std::fs::read_to_string(config_dir().join(file)).expect("shipped file");
    load(&text).unwrap_or_else(|e| panic!("the shipped {file} must load: {e}"));
    let doc: Value = Value::Table(toml::from_str(&text).expect("TOML"));
    let mut paths = Vec::new();
    leaves(&doc, Vec::new(), &mut paths);
    let mut failures = Vec::new();
    let mut n = 0;
    for p in &paths {
        for (class, key, bad) in mutations(&doc, p) {
            n += 1;
            let bad_text = toml::to_string(&bad).expect("serialise");
            match load(&bad_text) {
                Ok(()) => failures.push(format!("{file}: {} ({class}): accepted", show(p))),
                Err(msg) if !msg.contains(&key) => failures.push(format!(
                    "{file}: {} ({class}): the error does not name `{key}`: {msg}",
                    show(p)
                )),
                Err(_) => {}
            }
        }
    }
    (n, failures)
}

#[test]
fn every_pipeline_key_refuses_each_bad_class_naming_the_key() {
    let (n, failures) = check_every_key("pipeline.toml", |t| {
        microrobot_config::from_toml_str(t, "bad-pipeline.toml", &config_dir())
            .map(|_| ())
            .map_err(|e| e.to_string())
    });
    assert!(n > 100, "{n} mutations");
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn every_robot_key_refuses_each_bad_class_naming_the_key() {
    let (n, failures) = check_every_key("robots/seed-arm.toml", |t| {
        Robot::from_toml_str(t, "bad-arm.toml")
            .map(|_| ())
            .map_err(|e| e.to_string())
    });
    assert!(n > 50, "{n} mutations");
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn every_program_key_refuses_each_bad_class_naming_the_key() {
    let (n, failures) = check_every_key("programs/seed-table4.toml", |t| {
        Program::from_toml_str(t, "bad-program.toml")
            .map(|_| ())
            .map_err(|e| e.to_string())
    });
    assert!(n > 20, "{n} mutations");
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// The file is named in every error.
#[test]
fn errors_name_the_file() {
    let e = microrobot_config::from_toml_str("rate_hz = nan", "f1.toml", Path::new("/"))
        .expect_err("nan");
    assert!(e.to_string().starts_with("f1.toml"), "{e}");
    let e = Robot::from_toml_str("[robot]\nname = 1", "f2.toml").expect_err("type");
    assert!(e.to_string().starts_with("f2.toml"), "{e}");
    let e = Program::from_toml_str("[program]\nbogus = 1", "f3.toml").expect_err("unknown");
    assert!(e.to_string().starts_with("f3.toml"), "{e}");
}
