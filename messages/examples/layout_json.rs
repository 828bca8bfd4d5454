//! Prints the layout of every bus payload as JSON ([`microrobot_messages::layout`]): for
//! each type its iceoryx2 type name, size, alignment, and every field's offset and size.
//! `tools/python/check_layout.py` compares it with the Python (ctypes) mirror of the
//! contract, field by field.
//!
//! Run: `cargo run -q -p microrobot-messages --example layout_json`

use microrobot_messages::layout::payload_layouts;

fn main() {
    let types = payload_layouts();
    let n = types.len();
    let mut out = String::from("{\n");
    for (i, t) in types.iter().enumerate() {
        let fields: Vec<String> = t
            .fields
            .iter()
            .map(|(f, o, s)| format!("{{\"name\": \"{f}\", \"offset\": {o}, \"size\": {s}}}"))
            .collect();
        out.push_str(&format!(
            "  \"{}\": {{\"type_name\": \"{}\", \"size\": {}, \"align\": {}, \"fields\": [{}]}}{}\n",
            t.name,
            t.type_name,
            t.size,
            t.align,
            fields.join(", "),
            if i + 1 < n { "," } else { "" }
        ));
    }
    out.push('}');
    println!("{out}");
}
