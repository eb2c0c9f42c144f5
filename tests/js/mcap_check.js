// Reads MCAP files the way Foxglove does (@mcap/core's indexed reader, CRCs checked) and reports,
// per file, what a JavaScript consumer sees: JSON.parse on every message, stamps as JS numbers.
// Usage: node mcap_check.js FILE... ; prints one JSON object per file.
"use strict";
const fs = require("node:fs");
const { McapIndexedReader } = require("@mcap/core");
const { crc32 } = require("@foxglove/crc");
const { decompress } = require("fzstd");

function stampOf(value) {
  // A Foxglove Time {sec, nsec}; a bare number is what an old recording holds (JSON.parse rounds it).
  if (value !== null && typeof value === "object") {
    return BigInt(value.sec) * 1000000000n + BigInt(value.nsec);
  }
  return typeof value === "number" ? BigInt(Math.round(value)) : null;
}

function unsafeNumbers(value) {
  if (typeof value === "number") return Number.isSafeInteger(value) || !Number.isInteger(value) ? 0 : 1;
  if (value === null || typeof value !== "object") return 0;
  return Object.values(value).reduce((n, v) => n + unsafeNumbers(v), 0);
}

async function check(path) {
  const bytes = fs.readFileSync(path);
  const readable = {
    size: async () => BigInt(bytes.length),
    read: async (offset, length) => bytes.subarray(Number(offset), Number(offset + length)),
  };
  const reader = await McapIndexedReader.Initialize({
    readable,
    decompressHandlers: { zstd: (data, size) => decompress(data, new Uint8Array(Number(size))) },
  });
  const dataEnd = Number(reader.footer.summaryStart) - (1 + 8 + 4);
  const report = {
    path,
    messages: 0,
    data_section_crc: reader.dataSectionCrc ?? 0,
    data_section_crc_ok: reader.dataSectionCrc !== undefined &&
      crc32(bytes.subarray(0, dataEnd)) === reader.dataSectionCrc,
    publish_time_zero: 0,
    stamp_mismatch: {},
    timestamp_mismatch: {},
    unstamped: 0,
    unchecked: 0,
    json_errors: 0,
    unsafe_numbers: 0, // integers beyond Number.MAX_SAFE_INTEGER: JSON.parse has rounded them
  };
  for await (const m of reader.readMessages({ validateCrcs: true })) {
    report.messages += 1;
    if (m.publishTime === 0n) report.publish_time_zero += 1;
    const channel = reader.channelsById.get(m.channelId);
    if (channel.messageEncoding !== "json") continue;
    let obj;
    try {
      obj = JSON.parse(new TextDecoder().decode(m.data));
    } catch (e) {
      report.json_errors += 1;
      continue;
    }
    report.unsafe_numbers += unsafeNumbers(obj);
    // Our messages carry header.stamp; Foxglove views (no header) a timestamp, or one per entity.
    if (obj.header) {
      const stamp = stampOf(obj.header.stamp);
      if (stamp === 0n) {
        report.unstamped += 1;
      } else if (stamp !== m.logTime) {
        report.stamp_mismatch[channel.topic] = (report.stamp_mismatch[channel.topic] ?? 0) + 1;
      }
    }
    const stamps = obj.timestamp !== undefined ? [obj.timestamp] : [];
    for (const entity of obj.entities ?? []) stamps.push(entity.timestamp);
    // an ImageAnnotations (objects, pose) is stamped in each annotation
    for (const a of [...(obj.circles ?? []), ...(obj.points ?? []), ...(obj.texts ?? [])]) {
      stamps.push(a.timestamp);
    }
    if (stamps.some((t) => stampOf(t) !== m.logTime)) {
      report.timestamp_mismatch[channel.topic] = (report.timestamp_mismatch[channel.topic] ?? 0) + 1;
    }
    if (!obj.header && stamps.length === 0) report.unchecked += 1;
  }
  return report;
}

(async () => {
  for (const path of process.argv.slice(2)) {
    try {
      console.log(JSON.stringify(await check(path)));
    } catch (e) {
      console.log(JSON.stringify({ path, error: String(e && e.message ? e.message : e) }));
    }
  }
})();
