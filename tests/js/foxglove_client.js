// The npm Foxglove WebSocket client (@foxglove/ws-protocol) with its defaults, on the `ws`
// WebSocket its README names for Node.js: connects to URL, subscribes to TOPIC when advertised,
// prints one JSON line with the subprotocol agreed and the first message (JSON.parse'd), exits.
// Usage: node foxglove_client.js URL TOPIC
"use strict";
const { FoxgloveClient } = require("@foxglove/ws-protocol");
const { WebSocket } = require("ws");

const [url, topic] = process.argv.slice(2);
const ws = new WebSocket(url, [FoxgloveClient.SUPPORTED_SUBPROTOCOL]);
const client = new FoxgloveClient({ ws });
const report = { offered: FoxgloveClient.SUPPORTED_SUBPROTOCOL, subprotocol: null, server: null };
const channels = new Map();
const done = (extra, code) => {
  console.log(JSON.stringify({ ...report, ...extra }));
  process.exit(code);
};
const timer = setTimeout(() => done({ error: "nothing received in 60 s" }, 1), 60000);

ws.on("unexpected-response", (_req, res) => done({ error: `HTTP ${res.statusCode}` }, 1));
client.on("open", () => {
  report.subprotocol = ws.protocol;
});
client.on("error", (e) => done({ error: String(e && e.message ? e.message : e) }, 1));
client.on("serverInfo", (info) => {
  report.server = info.name;
});
client.on("advertise", (advertised) => {
  for (const channel of advertised) {
    if (channel.topic === topic && ![...channels.values()].includes(channel)) {
      channels.set(client.subscribe(channel.id), channel);
    }
  }
});
client.on("message", ({ subscriptionId, timestamp, data }) => {
  clearTimeout(timer);
  const channel = channels.get(subscriptionId);
  const text = new TextDecoder().decode(data);
  report.schemaName = channel.schemaName;
  report.logTime = timestamp.toString();
  report.message = JSON.parse(text);
  client.close();
  done({}, 0);
});
