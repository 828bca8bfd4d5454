//! Recording a lockstep run to MCAP and everything done with the file afterwards:
//! read back by the `mcap` crate's reader (counts per topic, JSON matching the schemas),
//! `export` (CSV rows), `plot` (PNGs), `replay` (torques bit for bit; an altered
//! setpoint is reported); a recorder killed mid-run leaves a file that `export` reads up
//! to its last complete chunk and `recover` finishes.

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::path::Path;

use crate::common::*;
use serde_json::Value;

/// Field names of `v`, nested ones as `outer.inner`.
fn keys(prefix: &str, v: &Value, out: &mut BTreeSet<String>) {
    if let Value::Object(m) = v {
        for (k, x) in m {
            let key = format!("{prefix}{k}");
            if x.is_object() {
                keys(&format!("{key}."), x, out);
            } else {
                out.insert(key);
            }
        }
    }
}

/// Property names of a JSON Schema, nested ones as `outer.inner`.
fn schema_keys(prefix: &str, s: &Value, out: &mut BTreeSet<String>) {
    if let Some(Value::Object(props)) = s.get("properties") {
        for (k, x) in props {
            let key = format!("{prefix}{k}");
            if x.get("type") == Some(&Value::from("object")) {
                schema_keys(&format!("{key}."), x, out);
            } else {
                out.insert(key);
            }
        }
    }
}

/// Reads `path` with the `mcap` crate: messages per topic, checking every message
/// against its channel's schema field names.
fn read_back(path: &Path) -> BTreeMap<String, Vec<Value>> {
    let bytes = std::fs::read(path).expect("read recording");
    let mut out: BTreeMap<String, Vec<Value>> = BTreeMap::new();
    let mut schema_fields: HashMap<String, BTreeSet<String>> = HashMap::new();
    let mut offsets: Option<i128> = None;
    let mut stamps: BTreeMap<String, Vec<u64>> = BTreeMap::new();
    for m in mcap::MessageStream::new(&bytes).expect("MCAP header") {
        let m = m.expect("MCAP message");
        let topic = m.channel.topic.clone();
        assert_eq!(m.channel.message_encoding, "json");
        let schema = m
            .channel
            .schema
            .as_ref()
            .expect("every channel has a schema");
        assert_eq!(schema.encoding, "jsonschema");
        let fields = schema_fields.entry(topic.clone()).or_insert_with(|| {
            let s: Value = serde_json::from_slice(&schema.data).expect("schema is JSON");
            let mut k = BTreeSet::new();
            schema_keys("", &s, &mut k);
            k
        });
        let v: Value = serde_json::from_slice(&m.data).expect("message is JSON");
        let mut k = BTreeSet::new();
        keys("", &v, &mut k);
        assert_eq!(&k, fields, "`{topic}` message fields vs its schema");
        // publish_time is the message's own CLOCK_MONOTONIC stamp (for the derived viewer
        // channels, the stamp of the message they derive from); log_time the same
        // instant on the wall clock: one offset for the whole file, the `clocks` one.
        if let Some(stamp) = v
            .get("header")
            .and_then(|h| h.get("stamp_ns"))
            .or_else(|| v.get("stamp_ns"))
            .and_then(Value::as_u64)
        {
            assert_eq!(
                m.publish_time, stamp,
                "`{topic}`: publish_time is the stamp"
            );
        } else {
            let t = match topic.as_str() {
                "transforms" => &v["transforms"][0]["timestamp"],
                "scene" => &v["entities"][0]["timestamp"],
                "joints" | "log" => &v["timestamp"],
                other => panic!("`{other}`: a message without its stamp"),
            };
            let wall =
                t["sec"].as_u64().expect("sec") * 1_000_000_000 + t["nsec"].as_u64().expect("nsec");
            assert_eq!(wall, m.log_time, "`{topic}`: its timestamp is its log time");
            stamps
                .entry(topic.clone())
                .or_default()
                .push(m.publish_time);
        }
        let offset = i128::from(m.log_time) - i128::from(m.publish_time);
        assert_eq!(
            *offsets.get_or_insert(offset),
            offset,
            "one clock offset per file"
        );
        out.entry(topic).or_default().push(v);
    }
    let offset = offsets.expect("messages were recorded");
    let wall_now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .expect("after 1970")
        .as_nanos() as i128;
    let mono_now = i128::from(microrobot_messages::monotonic_ns());
    assert!(
        (mono_now + offset - wall_now).abs() < 60_000_000_000,
        "log times are within a minute of the wall clock"
    );
    // The offset is in the file's `clocks` metadata, and chunks are zstd-compressed.
    let clocks: Vec<_> = mcap::read::LinearReader::new(&bytes)
        .expect("MCAP")
        .filter_map(|r| match r {
            Ok(mcap::records::Record::Metadata(m)) if m.name == "clocks" => Some(m),
            _ => None,
        })
        .collect();
    assert_eq!(clocks.len(), 1, "one `clocks` metadata record");
    assert_eq!(
        clocks[0].metadata["realtime_minus_monotonic_ns"],
        offset.to_string()
    );
    let chunk_compression: BTreeSet<String> = mcap::read::LinearReader::new(&bytes)
        .expect("MCAP")
        .filter_map(|r| match r {
            Ok(mcap::records::Record::Chunk { header, .. }) => Some(header.compression),
            _ => None,
        })
        .collect();
    assert_eq!(chunk_compression, BTreeSet::from(["zstd".to_string()]));
    // The viewer channels: the publish time of a derived message is the stamp of the
    // state (or setpoint) it was derived from; kept under `_stamps.<topic>`.
    for (topic, v) in stamps {
        out.entry(format!("_stamps.{topic}"))
            .or_default()
            .extend(v.into_iter().map(Value::from));
    }
    // The file is finished: summary and indexes present.
    let summary = mcap::Summary::read(&bytes)
        .expect("summary readable")
        .expect("the recorder finished the file (summary section)");
    assert!(!summary.chunk_indexes.is_empty(), "chunk indexes written");
    // Every chunk holds messages: Foxglove Studio refuses a chunk without a message index
    // (and its zero start time would stretch the file's time range back to 1970).
    for c in &summary.chunk_indexes {
        assert!(
            c.message_index_length > 0 && c.message_start_time > 0,
            "a chunk without messages at offset {}",
            c.chunk_start_offset
        );
    }
    out
}

/// Copies `src` to `dst`, passing each message's data through `edit(topic, position
/// in its topic, data)`, which returns the messages to write in its place.
fn rewrite(src: &Path, dst: &Path, mut edit: impl FnMut(&str, usize, Vec<u8>) -> Vec<Vec<u8>>) {
    let bytes = std::fs::read(src).expect("read recording");
    let file = std::fs::File::create(dst).expect("create altered copy");
    let mut w = mcap::WriteOptions::new()
        .compression(None)
        .create(std::io::BufWriter::new(file))
        .expect("writer");
    let mut channels: HashMap<u16, u16> = HashMap::new();
    let mut n: HashMap<String, usize> = HashMap::new();
    for m in mcap::MessageStream::new(&bytes).expect("MCAP header") {
        let m = m.expect("MCAP message");
        let id = match channels.get(&m.channel.id) {
            Some(id) => *id,
            None => {
                let s = m.channel.schema.as_ref().expect("schema");
                let sid = w.add_schema(&s.name, &s.encoding, &s.data).expect("schema");
                let cid = w
                    .add_channel(
                        sid,
                        &m.channel.topic,
                        &m.channel.message_encoding,
                        &m.channel.metadata,
                    )
                    .expect("channel");
                channels.insert(m.channel.id, cid);
                cid
            }
        };
        let k = n.entry(m.channel.topic.clone()).or_default();
        for data in edit(&m.channel.topic, *k, m.data.to_vec()) {
            w.write_to_known_channel(
                &mcap::records::MessageHeader {
                    channel_id: id,
                    sequence: m.sequence,
                    log_time: m.log_time,
                    publish_time: m.publish_time,
                },
                &data,
            )
            .expect("write");
        }
        *k += 1;
    }
    w.finish().expect("finish");
}

/// Copies `src` to `dst` with `q[0]` of the setpoint at position `which` changed.
fn alter_setpoint(src: &Path, dst: &Path, which: usize) -> u64 {
    let mut altered_seq = 0;
    rewrite(src, dst, |topic, k, data| {
        if topic != "setpoint" || k != which {
            return vec![data];
        }
        let mut v: Value = serde_json::from_slice(&data).expect("JSON");
        let q0 = v["q"][0].as_f64().expect("q_0");
        v["q"][0] = Value::from(q0 + 1e-3);
        altered_seq = v["header"]["seq"].as_u64().expect("seq");
        vec![serde_json::to_vec(&v).expect("JSON")]
    });
    altered_seq
}

/// Copies `src` to `dst` with one malformed message spliced in after message `which` of
/// each of `setpoint` (a setpoint with two joint values more than `dof` says: other
/// fields), `torque` (not JSON) and `state` (a field of the wrong type).
fn splice_malformed(src: &Path, dst: &Path, which: usize) {
    rewrite(src, dst, |topic, k, data| {
        if k != which {
            return vec![data];
        }
        let mut v: Value = serde_json::from_slice(&data).expect("JSON");
        let bad = match topic {
            "setpoint" => {
                let q = v["q"].as_array_mut().expect("q");
                q.extend([Value::from(0.0), Value::from(0.0)]);
                serde_json::to_vec(&v).expect("JSON")
            }
            "torque" => b"{\"header\": {\"seq\": 1,".to_vec(),
            "state" => {
                v["torque_seq"] = Value::from("seven");
                serde_json::to_vec(&v).expect("JSON")
            }
            _ => return vec![data],
        };
        vec![data, bad]
    });
}

#[test]
fn lockstep_run_recorded_exported_plotted_and_replayed_bit_for_bit() {
    let dir = tempfile::tempdir().expect("tempdir");
    let inst = instance("record");
    let cfg = write_config(dir.path(), &inst, &table4_lockstep_lines(), "");
    let cfg_s = cfg.to_str().expect("utf-8").to_string();
    let mcap_path = dir.path().join("run.mcap");
    let mcap_s = mcap_path.to_str().expect("utf-8").to_string();
    let ready = dir.path().join("recorder.ready");

    // The recorder first (it subscribes before the planner publishes anything), then the run.
    let rec = start(&[
        "record",
        "--instance",
        &inst,
        "--out",
        &mcap_s,
        "--until-finalized",
        "--ready-file",
        ready.to_str().expect("utf-8"),
    ]);
    let t0 = std::time::Instant::now();
    while !ready.exists() {
        assert!(t0.elapsed().as_secs() < 60, "recorder not ready in 60 s");
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    let summary_path = dir.path().join("summary.json");
    let out = run(
        &[
            "run",
            "--config",
            &cfg_s,
            "--lockstep",
            "--duration",
            "2",
            "--quiet",
            "--summary-json",
            summary_path.to_str().expect("utf-8"),
        ],
        180.0,
    );
    assert_eq!(out.code(), Some(0), "run; stderr:\n{}", out.stderr);
    let recorded = rec.finish(60.0);
    assert_eq!(
        recorded.code(),
        Some(0),
        "record; stderr:\n{}",
        recorded.stderr
    );
    let s = summary(&summary_path);
    let report: Value = serde_json::from_str(
        recorded
            .stdout
            .lines()
            .last()
            .expect("recorder prints a summary line"),
    )
    .expect("recorder summary is JSON");
    eprintln!("run cycles {}; recorder {report}", s["cycles"]);

    // Read back by the mcap crate.
    let topics = read_back(&mcap_path);
    let count = |t: &str| topics.get(t).map_or(0, Vec::len) as u64;
    let gaps = |t: &str| report["gaps"][t].as_u64().expect("gaps");
    let before_first = |t: &str| report["before_first"][t].as_u64().expect("before_first");
    for t in ["setpoint", "torque", "state", "status"] {
        assert!(count(t) > 0, "no `{t}` messages: {report}");
        assert_eq!(report["messages"][t], count(t), "{t}: {report}");
    }
    // Foxglove's transforms: the frames of the model's forward kinematics of the
    // recorded states (at 100 Hz), the tool among them.
    let robot = microrobot_model::Robot::from_file(&seed_arm()).expect("seed arm");
    let mut data = microrobot_model::ModelData::new(&robot);
    let states_by_stamp: HashMap<u64, &Value> = topics["state"]
        .iter()
        .map(|v| (v["header"]["stamp_ns"].as_u64().expect("stamp"), v))
        .collect();
    let tf_stamps = &topics["_stamps.transforms"];
    let mut checked = 0;
    for (tf, stamp) in topics["transforms"].iter().zip(tf_stamps) {
        let list = tf["transforms"].as_array().expect("transforms");
        let Some(tool) = list.iter().find(|t| t["child_frame_id"] == "tool") else {
            continue; // the commanded frames, under cmd/
        };
        let state = states_by_stamp[&stamp.as_u64().expect("stamp")];
        let mut q = microrobot_model::JointVector::zeros();
        for (i, x) in state["q"].as_array().expect("q").iter().enumerate() {
            q[i] = x.as_f64().expect("q_i");
        }
        let want = microrobot_model::tool_pose(&robot, &mut data, &q);
        for (axis, k) in ["x", "y", "z"].iter().enumerate() {
            let got = tool["translation"][k].as_f64().expect("number");
            assert!((got - want.translation[axis]).abs() < 1e-12, "tool {k}");
        }
        assert_eq!(list.len(), 7, "six joint frames and the tool");
        checked += 1;
    }
    assert!(
        checked > 10,
        "transforms recorded from the states: {checked}"
    );
    assert!(count("joints") > 10, "joints recorded");
    // The arm for the 3D panel: a line from the base through the joints to the tool.
    let scene = &topics["scene"][0]["entities"][0];
    assert_eq!(scene["frame_id"], "base_link");
    let line = scene["lines"][0]["points"].as_array().expect("points");
    assert_eq!(line.len(), 1 + 6 + 1, "base, six joints, tool");
    // Every service's log lines, as Foxglove's Log panel reads them: each service's
    // start-up line at INFO (2), under the service's name, with the target of the line.
    let logs = &topics["log"];
    for role in ["planner", "dynamics", "actuator"] {
        let started = logs.iter().find(|l| {
            l["name"] == role
                && l["level"] == 2
                && l["message"]
                    .as_str()
                    .is_some_and(|m| m.starts_with(&format!("{role} starting: instance")))
        });
        let started =
            started.unwrap_or_else(|| panic!("{role}'s start-up line in `log`: {logs:?}"));
        assert_eq!(started["file"], "microrobot_runtime", "the line's target");
    }
    let planner = s["cycles"]["planner"].as_u64().expect("planner cycles");
    let dynamics = s["cycles"]["dynamics"].as_u64().expect("dynamics cycles");
    assert!(planner > 100, "a 2 s lockstep run does many cycles: {s}");
    // Lockstep free-wheels (~5 kHz here): on a loaded 2-core machine the recorder can be
    // held off longer than the 64-sample queue lasts, at the start too (CI once lost the
    // first 77 setpoints to a 14 ms stall of the recorder's vCPU). Nothing may be lost
    // silently: what is missing is exactly what the recorder reports, as sequence gaps
    // or as messages sent before the first one it recorded (the recorder started first,
    // so those were lost, not missed by attaching late).
    let missing = |t: &str| gaps(t) + before_first(t);
    assert_eq!(
        count("setpoint") + missing("setpoint"),
        planner,
        "setpoints vs planner cycles: {report}"
    );
    assert_eq!(
        count("torque") + missing("torque"),
        dynamics,
        "torques vs dynamics cycles: {report}"
    );
    if missing("setpoint") + missing("torque") + missing("state") > 0 {
        eprintln!("warning: the recorder lost messages under load: {report}");
    }
    let seqs = |t: &str| {
        topics[t]
            .iter()
            .map(|v| v["header"]["seq"].as_u64().expect("seq"))
            .collect::<Vec<_>>()
    };
    // Numbered from 1: the last seq recorded is everything the stage published.
    let (setpoint_seqs, torque_seqs) = (seqs("setpoint"), seqs("torque"));
    assert_eq!(
        setpoint_seqs.last().copied(),
        Some(count("setpoint") + missing("setpoint"))
    );
    assert_eq!(
        torque_seqs.last().copied(),
        Some(count("torque") + missing("torque"))
    );
    assert_eq!(
        setpoint_seqs.first().copied(),
        Some(before_first("setpoint") + 1)
    );
    assert_eq!(topics["setpoint"][0]["q"].as_array().map(Vec::len), Some(6));

    // Export: one CSV per topic, a header plus one row per message.
    let csv_dir = dir.path().join("csv");
    let ex = run(
        &["export", &mcap_s, "--csv", csv_dir.to_str().expect("utf-8")],
        120.0,
    );
    assert_eq!(ex.code(), Some(0), "export; stderr:\n{}", ex.stderr);
    for t in ["setpoint", "torque", "state", "status"] {
        let text = std::fs::read_to_string(csv_dir.join(format!("{t}.csv"))).expect("csv");
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines.len() as u64, count(t) + 1, "{t}.csv rows");
        if t == "setpoint" {
            let head: Vec<&str> = lines[0].split(',').collect();
            assert!(head.contains(&"q_5") && !head.contains(&"q_6"), "{head:?}");
            assert!(head.contains(&"header.seq"), "{head:?}");
        }
    }

    // Plot: three non-empty PNGs.
    let png_dir = dir.path().join("png");
    let pl = run(
        &["plot", &mcap_s, "--out", png_dir.to_str().expect("utf-8")],
        180.0,
    );
    assert_eq!(pl.code(), Some(0), "plot; stderr:\n{}", pl.stderr);
    for f in ["torque.png", "tracking_error.png", "latency.png"] {
        let b = std::fs::read(png_dir.join(f)).expect("png");
        assert!(b.len() > 1000 && b.starts_with(b"\x89PNG"), "{f}");
    }

    // Replay: the torques again, bit for bit (config from the recording's attachment).
    assert_eq!(report["config_attached"], true, "{report}");
    let rp = run(&["replay", &mcap_s], 180.0);
    assert_eq!(rp.code(), Some(0), "replay; stderr:\n{}", rp.stderr);
    let r: Value = serde_json::from_str(rp.stdout.trim()).expect("replay report");
    assert_eq!(r["identical"], true, "{r}");
    // Torques whose setpoint or state the recorder lost cannot be recomputed.
    let compared = r["compared"].as_u64().expect("compared");
    assert!(compared * 10 >= count("torque") * 9, "{r}");
    assert_eq!(r["differences"], 0, "{r}");

    // Closed loop: the whole lockstep loop again in one process (planner, dynamics and
    // simulated arm, no IPC): every recorded setpoint, torque and state, bit for bit.
    let cl = run(&["replay", "--closed-loop", &mcap_s], 180.0);
    assert_eq!(
        cl.code(),
        Some(0),
        "closed-loop replay; stderr:\n{}",
        cl.stderr
    );
    let r: Value = serde_json::from_str(cl.stdout.trim()).expect("closed-loop report");
    assert_eq!(r["identical"], true, "{r}");
    assert_eq!(r["differences"], 0, "{r}");
    for (t, key) in [("setpoint", "setpoints"), ("torque", "torques")] {
        assert_eq!(r[key], count(t), "every recorded {t} compared: {r}");
    }
    // All states but the actuator's shutdown state (if recorded), which follows the loop.
    let states = r["states"].as_u64().expect("states");
    assert!(
        states == count("state") || states + 1 == count("state"),
        "every recorded state compared: {r}"
    );

    // A malformed message spliced into each of three topics: export and plot skip it,
    // and say how many they skipped per topic.
    let spliced = dir.path().join("spliced.mcap");
    let spliced_s = spliced.to_str().expect("utf-8");
    splice_malformed(&mcap_path, &spliced, 5);
    let csv2 = dir.path().join("csv-spliced");
    let ex = run(
        &["export", spliced_s, "--csv", csv2.to_str().expect("utf-8")],
        120.0,
    );
    assert_eq!(
        ex.code(),
        Some(0),
        "export of a spliced file; stderr:\n{}",
        ex.stderr
    );
    for t in ["setpoint", "torque", "state", "status"] {
        let text = std::fs::read_to_string(csv2.join(format!("{t}.csv"))).expect("csv");
        assert_eq!(
            text.lines().count() as u64,
            count(t) + 1,
            "{t}.csv: every well-formed message, the spliced one left out"
        );
        let skipped = u64::from(t != "status");
        assert!(
            ex.stderr.contains(&format!(
                "{t}.csv: {} rows ({skipped} malformed messages skipped)",
                count(t)
            )),
            "{t}: {}",
            ex.stderr
        );
    }
    for (t, why) in [
        ("setpoint", "other fields"),
        ("torque", "not valid JSON"),
        ("state", "torque_seq"),
    ] {
        assert!(
            ex.stderr.contains(&format!(
                "skipped 1 malformed `{t}` message (first: message 6: "
            )) && ex.stderr.contains(why),
            "{t}: {}",
            ex.stderr
        );
    }
    assert_eq!(
        std::fs::read_to_string(csv2.join("setpoint.csv")).expect("csv"),
        std::fs::read_to_string(csv_dir.join("setpoint.csv")).expect("csv"),
        "the same CSV as from the file without the malformed message"
    );
    let png2 = dir.path().join("png-spliced");
    let pl = run(
        &["plot", spliced_s, "--out", png2.to_str().expect("utf-8")],
        180.0,
    );
    assert_eq!(
        pl.code(),
        Some(0),
        "plot of a spliced file; stderr:\n{}",
        pl.stderr
    );
    for t in ["torque", "state"] {
        assert!(
            pl.stderr
                .contains(&format!("skipped 1 malformed `{t}` message")),
            "{t}: {}",
            pl.stderr
        );
    }
    assert!(png2.join("torque.png").exists());

    // An altered setpoint is reported, naming it.
    let altered = dir.path().join("altered.mcap");
    let seq = alter_setpoint(&mcap_path, &altered, (count("setpoint") / 2) as usize);
    let rp = run(
        &[
            "replay",
            altered.to_str().expect("utf-8"),
            "--config",
            &cfg_s,
        ],
        180.0,
    );
    assert_ne!(
        rp.code(),
        Some(0),
        "altered replay must fail: {}",
        rp.stdout
    );
    assert!(
        rp.stderr.contains(&format!("setpoint seq {seq} ")),
        "first difference names setpoint {seq}: {}",
        rp.stderr
    );
    let cl = run(
        &[
            "replay",
            "--closed-loop",
            altered.to_str().expect("utf-8"),
            "--config",
            &cfg_s,
        ],
        180.0,
    );
    assert_ne!(cl.code(), Some(0), "altered closed-loop replay must fail");
    assert!(
        cl.stderr
            .contains(&format!("setpoint seq {seq}: q[1] recorded")),
        "first difference names setpoint {seq} and its field: {}",
        cl.stderr
    );
}

#[test]
fn bad_recordings_are_refused_with_the_file_named() {
    let dir = tempfile::tempdir().expect("tempdir");
    let junk = dir.path().join("junk.mcap");
    std::fs::write(&junk, b"not an mcap file").expect("write");
    let junk_s = junk.to_str().expect("utf-8");
    for args in [
        vec!["replay", junk_s],
        vec!["export", junk_s, "--csv", "/tmp"],
        vec!["plot", junk_s, "--out", "/tmp"],
    ] {
        let out = run(&args, 60.0);
        assert_eq!(out.code(), Some(1), "{args:?}");
        assert!(out.stderr.contains("junk.mcap"), "{args:?}: {}", out.stderr);
    }
    let missing = run(&["replay", "/nonexistent/x.mcap"], 60.0);
    assert_eq!(missing.code(), Some(1));
    assert!(
        missing.stderr.contains("/nonexistent/x.mcap"),
        "{}",
        missing.stderr
    );
}

/// A recorder killed with SIGKILL mid-run: `export` reads the file up to its last
/// complete chunk (at most a second of messages lost) and says where it was cut;
/// `recover` writes a finished, indexed copy with every message read.
#[test]
fn a_killed_recorder_leaves_a_file_export_reads_and_recover_finishes() {
    let dir = tempfile::tempdir().expect("tempdir");
    let inst = instance("rec-kill");
    let cfg = write_config(dir.path(), &inst, "", "");
    let mcap_path = dir.path().join("killed.mcap");
    let ready = dir.path().join("ready");
    let rec = start(&[
        "record",
        "--instance",
        &inst,
        "--out",
        mcap_path.to_str().expect("utf-8"),
        "--ready-file",
        ready.to_str().expect("utf-8"),
    ]);
    let t0 = std::time::Instant::now();
    while !ready.exists() {
        assert!(t0.elapsed().as_secs() < 60, "recorder not ready in 60 s");
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    let pipeline = start(&[
        "run",
        "--config",
        cfg.to_str().expect("utf-8"),
        "--no-program",
        "--duration",
        "8",
        "--quiet",
    ]);
    // Well past the first flushed chunks (one per second of messages) after the pipeline
    // is up (its start takes longer on a loaded machine), then SIGKILL.
    wait_ready(&inst, 60.0);
    std::thread::sleep(std::time::Duration::from_secs(3));
    rec.signal(libc::SIGKILL);
    let _ = rec.finish(30.0);
    let done = pipeline.finish(120.0);
    assert_eq!(
        done.code(),
        Some(0),
        "the pipeline runs on: {}",
        done.stderr
    );

    let export = |file: &Path, out: &Path| {
        run(
            &[
                "export",
                file.to_str().expect("utf-8"),
                "--out",
                out.to_str().expect("utf-8"),
            ],
            60.0,
        )
    };
    let out = dir.path().join("csv");
    let exported = export(&mcap_path, &out);
    assert_eq!(exported.code(), Some(0), "{}", exported.stderr);
    assert!(
        exported.stderr.contains("the file ends early"),
        "the cut is said: {}",
        exported.stderr
    );
    let rows = |dir: &Path, t: &str| {
        std::fs::read_to_string(dir.join(format!("{t}.csv")))
            .expect("csv")
            .lines()
            .count()
            - 1
    };
    let setpoints = rows(&out, "setpoint");
    // The run held the arm for 3 s or more before the kill at 1 kHz: at most the last
    // second (the open chunk) is lost.
    assert!(setpoints >= 1500, "{setpoints} setpoints before the kill");

    let recovered = dir.path().join("recovered.mcap");
    let r = run(
        &[
            "recover",
            mcap_path.to_str().expect("utf-8"),
            recovered.to_str().expect("utf-8"),
        ],
        60.0,
    );
    assert_eq!(r.code(), Some(0), "{}", r.stderr);
    assert!(r.stderr.contains("ends early"), "{}", r.stderr);
    // The copy is finished: summary, indexes, and the same messages.
    let bytes = std::fs::read(&recovered).expect("recovered");
    let summary = mcap::Summary::read(&bytes)
        .expect("summary readable")
        .expect("a finished file has a summary");
    assert!(!summary.chunk_indexes.is_empty());
    let n = mcap::MessageStream::new(&bytes)
        .expect("MCAP")
        .filter(|m| m.as_ref().is_ok_and(|m| m.channel.topic == "setpoint"))
        .count();
    assert_eq!(n, setpoints, "recover keeps every message export read");
    let again = dir.path().join("csv2");
    let e2 = export(&recovered, &again);
    assert_eq!(e2.code(), Some(0), "{}", e2.stderr);
    assert!(!e2.stderr.contains("ends early"), "{}", e2.stderr);
    assert_eq!(rows(&again, "setpoint"), setpoints);
}
