// Reads a seqloc ROS 2 bag back with the readers others use: @mcap/core (the MCAP library of the
// format's authors) and @foxglove/rosmsg + @foxglove/rosmsg2-serialization (the ROS 2 .msg parser
// and CDR decoder behind Foxglove). Prints one JSON document: the header, schemas, channels,
// statistics, metadata and every message decoded, for check_bags.py to compare with poses.csv.
//
//   node read_bag.mjs BAG.mcap
//
// The file is read twice: through its summary and indexes (McapIndexedReader, as Foxglove and
// rosbag2 seek) and front to back with every CRC checked (McapStreamReader); both must agree.
import { open, readFile } from "node:fs/promises";
import { McapIndexedReader, McapStreamReader } from "@mcap/core";
import { parse } from "@foxglove/rosmsg";
import { MessageReader } from "@foxglove/rosmsg2-serialization";

const path = process.argv[2];
if (!path) {
  console.error("usage: node read_bag.mjs BAG.mcap");
  process.exit(2);
}

function fail(what) {
  console.error(`read_bag: ${path}: ${what}`);
  process.exit(1);
}

async function readIndexed(handle) {
  const size = BigInt((await handle.stat()).size);
  const readable = {
    size: async () => size,
    read: async (offset, length) => {
      const buffer = new Uint8Array(Number(length));
      const { bytesRead } = await handle.read(buffer, 0, Number(length), Number(offset));
      if (bytesRead !== Number(length)) fail(`short read at ${offset}`);
      return buffer;
    },
  };
  return McapIndexedReader.Initialize({ readable });
}

// Every record front to back, CRCs validated (the data section's, each chunk's, the summary's).
function readStream(bytes) {
  const reader = new McapStreamReader({ validateCrcs: true });
  reader.append(bytes);
  const records = [];
  for (let r; (r = reader.nextRecord()); ) records.push(r);
  if (!reader.done()) fail("the stream reader did not reach the closing magic");
  return records;
}

// A decoded message as plain JSON: bigints as strings, NaN as the string "NaN", typed arrays as arrays.
function plain(value) {
  if (typeof value === "bigint") return value.toString();
  if (typeof value === "number" && Number.isNaN(value)) return "NaN";
  if (ArrayBuffer.isView(value)) return Array.from(value, plain);
  if (Array.isArray(value)) return value.map(plain);
  if (value && typeof value === "object") {
    return Object.fromEntries(Object.entries(value).map(([k, v]) => [k, plain(v)]));
  }
  return value;
}

const handle = await open(path, "r");
const indexed = await readIndexed(handle);
const bytes = new Uint8Array(await readFile(path));
const streamed = readStream(bytes);

const readers = new Map();
for (const [id, schema] of indexed.schemasById) {
  if (schema.encoding !== "ros2msg") fail(`schema ${schema.name} is ${schema.encoding}, not ros2msg`);
  const text = new TextDecoder().decode(schema.data);
  readers.set(id, new MessageReader(parse(text, { ros2: true })));
}

const messages = [];
for await (const m of indexed.readMessages({ validateCrcs: true })) {
  const channel = indexed.channelsById.get(m.channelId);
  if (channel.messageEncoding !== "cdr") fail(`channel ${channel.topic} is ${channel.messageEncoding}, not cdr`);
  const reader = readers.get(channel.schemaId);
  const message = reader.readMessage(m.data);
  if (reader.lastReadHadTrailingBytes()) fail(`${channel.topic} message ${m.sequence} has bytes its schema does not cover`);
  messages.push({
    topic: channel.topic,
    sequence: m.sequence,
    log_time: m.logTime.toString(),
    publish_time: m.publishTime.toString(),
    message: plain(message),
  });
}

// The stream reader's messages must be the indexed reader's, in the same order and with the same bytes.
const streamedMessages = streamed.filter((r) => r.type === "Message");
if (streamedMessages.length !== messages.length) {
  fail(`${streamedMessages.length} messages front to back, ${messages.length} through the index`);
}
streamedMessages.forEach((m, i) => {
  const topic = indexed.channelsById.get(m.channelId).topic;
  if (topic !== messages[i].topic || m.logTime.toString() !== messages[i].log_time) {
    fail(`message ${i}: ${topic}@${m.logTime} front to back, ${messages[i].topic}@${messages[i].log_time} by index`);
  }
});

const metadata = [];
for await (const m of indexed.readMetadata()) metadata.push({ name: m.name, metadata: Object.fromEntries(m.metadata) });

await handle.close();

const stats = indexed.statistics;
console.log(
  JSON.stringify({
    header: indexed.header,
    data_section_crc: indexed.dataSectionCrc ?? null,
    record_types: [...new Set(streamed.map((r) => r.type))],
    schemas: [...indexed.schemasById.values()].map((s) => ({ id: s.id, name: s.name, encoding: s.encoding })),
    channels: [...indexed.channelsById.values()].map((c) => ({
      id: c.id,
      topic: c.topic,
      schema_id: c.schemaId,
      message_encoding: c.messageEncoding,
    })),
    statistics: stats && {
      message_count: stats.messageCount.toString(),
      channel_message_counts: Object.fromEntries([...stats.channelMessageCounts].map(([k, v]) => [k, v.toString()])),
      message_start_time: stats.messageStartTime.toString(),
      message_end_time: stats.messageEndTime.toString(),
      chunk_count: stats.chunkCount,
    },
    chunk_indexes: indexed.chunkIndexes.length,
    metadata,
    messages,
  }),
);
