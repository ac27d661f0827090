// A Foxglove WebSocket client for the live_view tests: @foxglove/ws-protocol's FoxgloveClient over
// `ws`, each channel's ros2msg schema parsed by @foxglove/rosmsg and its CDR messages decoded by
// @foxglove/rosmsg2-serialization (the parser stack Foxglove itself uses).
//
//   node client.mjs URL SECONDS TOPIC[,TOPIC...]
//
// Subscribes to the listed topics (all advertised ones for "*") for SECONDS after the first
// advertisement and prints one JSON object: the advertised channels, per topic the message
// count, the receive times [ms] and the first and last decoded messages. Exit 1 on a schema or
// message that does not decode, or when the server cannot be reached.
import wsProtocol from "@foxglove/ws-protocol";
import { parse } from "@foxglove/rosmsg";
import { MessageReader } from "@foxglove/rosmsg2-serialization";
import WebSocket from "ws";

const { FoxgloveClient } = wsProtocol;
// foxglove-sdk 0.30 accepts only the SDK's name of the protocol, "foxglove.sdk.v1" (the
// messages this client reads are those of ws-protocol's "foxglove.websocket.v1", offered too).
const SUBPROTOCOLS = ["foxglove.sdk.v1", FoxgloveClient.SUPPORTED_SUBPROTOCOL];
const [url, secondsText, topicsText] = process.argv.slice(2);
const seconds = Number(secondsText);
const wanted = topicsText === "*" ? null : new Set(topicsText.split(","));

const channels = [];
const bySubscription = new Map();
const result = { channels, counts: {}, times: {}, first: {}, last: {}, problems: [] };

function plain(value) {
  // Typed arrays and bigints as JSON numbers and arrays.
  return JSON.parse(
    JSON.stringify(value, (_key, v) => {
      if (typeof v === "bigint") return Number(v);
      if (ArrayBuffer.isView(v) && !(v instanceof DataView)) return Array.from(v);
      return v;
    }),
  );
}

const client = new FoxgloveClient({ ws: new WebSocket(url, SUBPROTOCOLS) });
let timer = null;
function finish(code) {
  client.close();
  // Exit once the JSON is written: process.exit() right after a write to a pipe cuts it at 64 KiB.
  process.stdout.write(JSON.stringify(result) + "\n", () => process.exit(code));
}
client.on("error", (error) => {
  result.problems.push(`connection: ${error?.message ?? error}`);
  finish(1);
});
client.on("advertise", (advertised) => {
  for (const channel of advertised) {
    channels.push({
      topic: channel.topic,
      encoding: channel.encoding,
      schemaName: channel.schemaName,
      schemaEncoding: channel.schemaEncoding,
    });
    if (wanted !== null && !wanted.has(channel.topic)) continue;
    try {
      if (channel.schemaEncoding !== "ros2msg") throw new Error(`schema encoding ${channel.schemaEncoding}`);
      const reader = new MessageReader(parse(channel.schema, { ros2: true }));
      bySubscription.set(client.subscribe(channel.id), { topic: channel.topic, reader });
    } catch (error) {
      result.problems.push(`schema of ${channel.topic}: ${error.message}`);
    }
  }
  if (timer === null) timer = setTimeout(() => finish(result.problems.length ? 1 : 0), seconds * 1000);
});
client.on("message", ({ subscriptionId, data }) => {
  const entry = bySubscription.get(subscriptionId);
  if (entry === undefined) return;
  const { topic, reader } = entry;
  try {
    const bytes = new Uint8Array(data.buffer, data.byteOffset, data.byteLength);
    const message = plain(reader.readMessage(bytes));
    result.counts[topic] = (result.counts[topic] ?? 0) + 1;
    (result.times[topic] ??= []).push(performance.now());
    if (!(topic in result.first)) result.first[topic] = message;
    result.last[topic] = message;
  } catch (error) {
    if (result.problems.length < 20) result.problems.push(`${topic}: ${error.message}`);
  }
});
