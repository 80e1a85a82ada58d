// Reads an MCAP file with the format's reference implementation (@mcap/core) and decodes every
// message with Foxglove's OMG IDL parser and CDR reader, as Foxglove does:
//   node check.cjs FILE.mcap
// Prints one JSON line per message in log time order ({topic, log_time, publish_time, sequence,
// derived, data}; 64-bit integers as strings; derived: a channel cpm adds for viewers), then one
// line of totals. Exits 1 naming what is wrong:
// a CRC (chunks, data section, summary), a record, a schema that does not parse, a message that
// does not decode.
"use strict";
const fs = require("fs");
const { McapIndexedReader, McapStreamReader } = require("@mcap/core");
const { crc32 } = require("@foxglove/crc");
const { parseIDL } = require("@foxglove/omgidl-parser");
const { MessageReader } = require("@foxglove/omgidl-serialization");

function fail(what) {
  process.stderr.write(`mcap check: ${process.argv[2]}: ${what}\n`);
  process.exit(1);
}

function plain(value) {
  if (typeof value === "bigint") return value.toString();
  if (ArrayBuffer.isView(value)) return Array.from(value, plain);
  if (Array.isArray(value)) return value.map(plain);
  if (value && typeof value === "object") {
    const out = {};
    for (const [k, v] of Object.entries(value)) out[k] = plain(v);
    return out;
  }
  return value;
}

async function main() {
  const path = process.argv[2];
  if (!path) fail("usage: node check.cjs FILE.mcap");
  const bytes = fs.readFileSync(path);

  // The whole file as a stream: every record parsed, every chunk's CRC checked.
  const stream = new McapStreamReader({ validateCrcs: true });
  stream.append(bytes);
  let streamed = 0;
  let dataEndCrc;
  for (let record; (record = stream.nextRecord()); ) {
    if (record.type === "Message") ++streamed;
    if (record.type === "DataEnd") dataEndCrc = record.dataSectionCrc;
  }
  if (!stream.done()) fail("the stream reader did not reach the end of the file");

  // The indexed reader, as a viewer seeks: summary CRC checked on opening.
  const readable = {
    size: async () => BigInt(bytes.length),
    read: async (offset, length) => bytes.subarray(Number(offset), Number(offset + length)),
  };
  const reader = await McapIndexedReader.Initialize({ readable });
  if (reader.chunkIndexes.length === 0) fail("no chunk indexes");
  const summaryStart = Number(reader.footer.summaryStart);
  if (summaryStart === 0) fail("no summary");
  // The data section's CRC (neither reader checks it): from the magic to the Data End record.
  if (dataEndCrc !== undefined && dataEndCrc !== 0) {
    const crc = crc32(bytes.subarray(0, summaryStart - 13));
    if (crc !== dataEndCrc) fail(`the data section's CRC is ${crc}, Data End says ${dataEndCrc}`);
  }

  const decoders = new Map();
  const decoderOf = (channel) => {
    if (decoders.has(channel.id)) return decoders.get(channel.id);
    const schema = reader.schemasById.get(channel.schemaId);
    let decoder = null;
    if (schema) {
      if (schema.encoding !== "omgidl") fail(`schema ${schema.name}: encoding ${schema.encoding}`);
      if (channel.messageEncoding !== "cdr") fail(`channel ${channel.topic}: message encoding ${channel.messageEncoding}`);
      try {
        const text = new TextDecoder().decode(schema.data);
        decoder = new MessageReader(schema.name, parseIDL(text));
      } catch (e) {
        fail(`schema ${schema.name} does not parse: ${e.message}`);
      }
    }
    decoders.set(channel.id, decoder);
    return decoder;
  };

  let read = 0;
  let last = -1n;
  for await (const m of reader.readMessages({ validateCrcs: true })) {
    if (m.logTime < last) fail(`message ${read} is older than the one before it`);
    last = m.logTime;
    const channel = reader.channelsById.get(m.channelId);
    const decoder = decoderOf(channel);
    let data = null;
    if (decoder) {
      try {
        data = plain(decoder.readMessage(m.data));
      } catch (e) {
        fail(`message ${read} on ${channel.topic} does not decode: ${e.message}`);
      }
    }
    process.stdout.write(
      JSON.stringify({
        topic: channel.topic,
        log_time: m.logTime.toString(),
        publish_time: m.publishTime.toString(),
        sequence: m.sequence,
        derived: channel.metadata.has("cpm.derived"),
        data,
      }) + "\n",
    );
    ++read;
  }
  if (read !== streamed) fail(`the index reads ${read} messages, the stream ${streamed}`);
  const stats = reader.statistics;
  if (stats && Number(stats.messageCount) !== read) fail(`Statistics says ${stats.messageCount} messages, ${read} read`);
  process.stdout.write(
    JSON.stringify({
      messages: read,
      channels: reader.channelsById.size,
      schemas: reader.schemasById.size,
      chunks: reader.chunkIndexes.length,
      metadata: reader.metadataIndexes.map((i) => i.name),
    }) + "\n",
  );
}

main().catch((e) => fail(e.message));
