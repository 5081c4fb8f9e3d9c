// A Sparkplug B host application for the tests, whose decoding none of this project
// wrote: Eclipse Tahu's JavaScript payload codec (npm sparkplug-payload, generated
// from the specification's sparkplug_b.proto by protobufjs) over mqtt.js.
//
//   node host.js mqtt://127.0.0.1:PORT
//
// It subscribes to spBv1.0/# and does what a host does with an edge node's messages:
// learns each metric's name and datatype from the births, reads a data message's
// metrics by alias with the datatype born (a data message leaves it off, as the
// specification has it: Tahu's decoder picks a value's field by the datatype, so the
// host puts the born one back before decoding), follows seq and bdSeq.  One JSON line
// per message on stdout: {kind, topic, seq, timestamp, bdSeq, metrics: [{name, alias,
// type, value, timestamp, historical}], problems: [...]}; "problems" says what a host
// could not make sense of (data before a birth, an alias never born, a seq gap, an
// NDEATH of another session, a value it could not read).  {"event": "ready"} once
// subscribed.
"use strict";
const mqtt = require("mqtt");
const { decodePayload } = require("sparkplug-payload/lib/sparkplugbpayload");
const proto = require("sparkplug-payload/lib/sparkplugPayloadProto").org.eclipse.tahu.protobuf;

const url = process.argv[2];
const client = mqtt.connect(url, { clientId: `tahu-host-${process.pid}`, clean: true, protocolVersion: 4,
  reconnectPeriod: 200 });
const nodes = new Map(); // "group/edge" -> { aliases: Map("device|alias" -> {name, type}), seq, bdSeq, born }

function plain(v) {
  if (v === null || v === undefined) return v === undefined ? "undefined" : null;
  if (typeof v === "object" && typeof v.toNumber === "function") return v.toNumber(); // Long
  if (v instanceof Uint8Array) return Buffer.from(v).toString("hex");
  if (typeof v === "number" && !Number.isFinite(v)) return String(v);
  return v;
}

function out(o) {
  process.stdout.write(JSON.stringify(o) + "\n");
}

client.on("connect", () => {
  client.subscribe("spBv1.0/#", { qos: 1 }, (err) => out(err ? { event: "error", error: String(err) }
    : { event: "ready" }));
});
client.on("error", (err) => out({ event: "error", error: String(err) }));

client.on("message", (topic, buf) => {
  const parts = topic.split("/");
  const kind = parts[2];
  if (parts[1] === "STATE" || kind === "NCMD" || kind === "DCMD") return;
  const key = `${parts[1]}/${parts[3]}`;
  const device = parts[4] || "";
  const problems = [];
  let node = nodes.get(key);
  let raw;
  try {
    raw = proto.Payload.decode(buf);
  } catch (err) {
    out({ kind, topic, problems: [`not a Sparkplug payload: ${err}`] });
    return;
  }
  if (kind === "NBIRTH") {
    node = { aliases: new Map(), seq: null, bdSeq: null, born: true };
    nodes.set(key, node);
  } else if (!node || !node.born) {
    if (kind !== "NDEATH") problems.push(`${kind} before any NBIRTH`);
    node = node || { aliases: new Map(), seq: null, bdSeq: null, born: false };
    nodes.set(key, node);
  }
  if (kind === "DDATA" || kind === "NDATA") { // by alias: the born datatype back, for Tahu's decoder
    for (const m of raw.metrics) {
      const born = node.aliases.get(`${device}|${m.alias}`);
      if (!Object.prototype.hasOwnProperty.call(m, "alias") || !born) {
        problems.push(`metric ${m.name || m.alias} never born`);
      } else if (!Object.prototype.hasOwnProperty.call(m, "datatype")) {
        m.datatype = born.typeInt;
      }
    }
  }
  const p = decodePayload(proto.Payload.encode(raw).finish());
  const metrics = (p.metrics || []).map((m) => {
    const born = m.alias !== undefined ? node.aliases.get(`${device}|${plain(m.alias)}`) : undefined;
    return { name: m.name !== undefined ? m.name : born && born.name, alias: plain(m.alias),
      type: m.type || (born && born.type), value: plain(m.value), timestamp: plain(m.timestamp),
      historical: m.isHistorical === true };
  });
  if (kind === "NBIRTH" || kind === "DBIRTH") {
    raw.metrics.forEach((m, i) => {
      if (Object.prototype.hasOwnProperty.call(m, "alias")) {
        node.aliases.set(`${device}|${plain(m.alias)}`, { name: m.name, typeInt: m.datatype, type: metrics[i].type });
      }
    });
  }
  const seq = p.seq !== undefined ? plain(p.seq) : null;
  if (kind === "NBIRTH") {
    node.bdSeq = (metrics.find((m) => m.name === "bdSeq") || {}).value;
    if (seq !== 0) problems.push(`NBIRTH seq ${seq}`);
  } else if (kind === "NDEATH") {
    const bd = (metrics.find((m) => m.name === "bdSeq") || {}).value;
    if (node.born && bd !== node.bdSeq) problems.push(`NDEATH bdSeq ${bd}, born with ${node.bdSeq}`);
    node.born = false;
  } else if (node.seq !== null && seq !== (node.seq + 1) % 256) {
    problems.push(`seq ${seq} after ${node.seq}`);
  }
  if (kind !== "NDEATH") node.seq = seq;
  for (const m of metrics) {
    if (m.value === "undefined") problems.push(`no value read for ${m.name} (${m.type})`);
  }
  out({ kind, topic, seq, timestamp: plain(p.timestamp), metrics, problems });
});

process.stdin.on("end", () => client.end(true, () => process.exit(0)));
process.stdin.resume();
