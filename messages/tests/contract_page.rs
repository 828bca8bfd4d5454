//! The contract page (`messages/README.md`) against the compiled payloads: every payload
//! with a table of offsets there states its true size in its heading, and its table
//! lists exactly the type's fields at their true offsets. A driver author who builds a
//! struct from the page gets the layout iceoryx2 will accept.

use microrobot_messages::layout::payload_layouts;

/// A payload section of the page: its heading's type name, the size it states, and its
/// table rows (offset, field).
struct Section {
    name: String,
    stated_size: Option<usize>,
    rows: Vec<(usize, String)>,
}

/// `### \`Name\` (\`microrobot::v2::Name\`, 296 B ...` headings and the `| offset | field |`
/// tables under them.
fn sections(page: &str) -> Vec<Section> {
    let mut out: Vec<Section> = Vec::new();
    let mut in_table = false;
    for line in page.lines() {
        if let Some(rest) = line.strip_prefix("### `") {
            in_table = false;
            let Some((name, after)) = rest.split_once('`') else {
                continue;
            };
            let stated_size = after
                .split_once("`, ")
                .and_then(|(_, s)| s.split_once(" B"))
                .and_then(|(n, _)| n.trim().parse().ok());
            out.push(Section {
                name: name.to_string(),
                stated_size,
                rows: Vec::new(),
            });
            continue;
        }
        if line.starts_with("| offset | field |") {
            in_table = true;
            continue;
        }
        if !line.starts_with('|') {
            in_table = false;
            continue;
        }
        if !in_table || line.starts_with("|---") {
            continue;
        }
        let cells: Vec<&str> = line.split('|').map(str::trim).collect();
        let (Some(offset), Some(field)) = (cells.get(1), cells.get(2)) else {
            continue;
        };
        let (Ok(offset), Some(last)) = (offset.parse::<usize>(), out.last_mut()) else {
            continue;
        };
        last.rows
            .push((offset, field.trim_matches('`').to_string()));
    }
    out
}

#[test]
fn every_offset_table_on_the_contract_page_matches_the_compiled_payload() {
    let page = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/README.md"))
        .expect("messages/README.md");
    let sections = sections(&page);
    let layouts = payload_layouts();
    let mut checked = Vec::new();
    let mut errors = Vec::new();
    for s in sections.iter().filter(|s| !s.rows.is_empty()) {
        let Some(l) = layouts.iter().find(|l| l.name == s.name) else {
            errors.push(format!("`{}`: a table on the page for no payload", s.name));
            continue;
        };
        checked.push(l.name);
        match s.stated_size {
            Some(n) if n == l.size => {}
            Some(n) => errors.push(format!(
                "`{}`: heading says {n} B, it is {} B",
                l.name, l.size
            )),
            None => errors.push(format!(
                "`{}`: heading states no size ({} B)",
                l.name, l.size
            )),
        }
        let want: Vec<(usize, String)> = l
            .fields
            .iter()
            .map(|&(f, o, _)| (o, f.to_string()))
            .collect();
        if s.rows != want {
            errors.push(format!(
                "`{}`: the page lists {:?}, the type has {:?}",
                l.name, s.rows, want
            ));
        }
    }
    assert!(errors.is_empty(), "{}", errors.join("\n"));
    // The payloads a driver builds or reads field by field all have a table.
    for name in [
        "Header",
        "JointSetpoint",
        "TorqueCommand",
        "JointState",
        "MotionCommand",
        "MasterPose",
        "ServiceStatus",
    ] {
        assert!(checked.contains(&name), "no offset table for `{name}`");
    }
}

#[test]
fn the_page_parser_sees_a_wrong_offset() {
    let page = "### `Header` (`microrobot::v2::Header`, 32 B) — x\n\
                | offset | field | type | meaning |\n|---|---|---|---|\n\
                | 0 | `seq` | u64 | |\n| 8 | `tick` | u64 | |\n\
                | 24 | `stamp_ns` | u64 | |\n| 24 | `source_stamp_ns` | u64 | |\n";
    let s = sections(page);
    assert_eq!(s.len(), 1);
    assert_eq!(s[0].stated_size, Some(32));
    let header = payload_layouts()
        .into_iter()
        .find(|l| l.name == "Header")
        .expect("Header");
    let want: Vec<(usize, String)> = header
        .fields
        .iter()
        .map(|&(f, o, _)| (o, f.to_string()))
        .collect();
    assert_ne!(
        s[0].rows, want,
        "a stamp at 24 instead of 16 must not match"
    );
}
