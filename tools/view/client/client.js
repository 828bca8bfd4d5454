// A Foxglove WebSocket client for the system test of `microrobot view`, built on the
// official client (@foxglove/ws-protocol) over `ws`.
//
//   node client.js URL collect SECONDS   subscribe to every channel; print one JSON line:
//                                        the server's name, each channel (schema name and
//                                        encoding, message count) and its last messages
//   node client.js URL stall SECONDS     subscribe to every channel, then stop reading the
//                                        socket for SECONDS (a client that stalls)
"use strict";
const { FoxgloveClient } = require("@foxglove/ws-protocol");
const WebSocket = require("ws");

const [url, mode, seconds] = process.argv.slice(2);
if (!url || !["collect", "stall"].includes(mode) || !(Number(seconds) > 0)) {
  console.error("usage: node client.js URL collect|stall SECONDS");
  process.exit(2);
}
// Foxglove's Rust SDK names the ws-protocol v1 wire format (inline schemas in the
// advertisements) `foxglove.sdk.v1`; the client speaks it as `foxglove.websocket.v1`.
const ws = new WebSocket(url, [FoxgloveClient.SUPPORTED_SUBPROTOCOL, "foxglove.sdk.v1"]);
const client = new FoxgloveClient({ ws });
// Last messages kept per channel (more of the two the test matches by log time).
const keep = (topic) => (topic === "transforms" || topic === "joints" ? 200 : 2);
const channels = new Map(); // subscription id -> record
const byTopic = {};
let serverName = null;

client.on("error", (e) => {
  console.error(`client error: ${e && e.message ? e.message : e}`);
  process.exit(1);
});
client.on("serverInfo", (info) => {
  serverName = info.name;
});
client.on("advertise", (list) => {
  for (const ch of list) {
    const rec = {
      schemaName: ch.schemaName,
      schemaEncoding: ch.schemaEncoding,
      encoding: ch.encoding,
      count: 0,
      keep: keep(ch.topic),
      last: [],
    };
    byTopic[ch.topic] = rec;
    channels.set(client.subscribe(ch.id), rec);
  }
  if (mode === "stall" && channels.size > 0 && !ws.isPaused) {
    ws.pause(); // stop reading: the server's queue for this client fills
    console.log(JSON.stringify({ stalled: true, channels: channels.size }));
  }
});
const decoder = new TextDecoder();
client.on("message", ({ subscriptionId, timestamp, data }) => {
  const rec = channels.get(subscriptionId);
  if (!rec) return;
  rec.count += 1;
  let value;
  try {
    value = JSON.parse(decoder.decode(data));
  } catch (e) {
    value = { undecodable: String(e) };
  }
  rec.last.push({ log_time: timestamp.toString(), value });
  if (rec.last.length > rec.keep) rec.last.shift();
});
setTimeout(() => {
  ws.terminate();
  const out = mode === "collect" ? JSON.stringify({ server: serverName, channels: byTopic }) : "";
  // Exit once the line is written: a pipe takes it asynchronously.
  process.stdout.write(out + "\n", () => process.exit(0));
}, Number(seconds) * 1000);
