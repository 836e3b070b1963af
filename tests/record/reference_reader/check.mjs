// Reads recordings with @mcap/core, the MCAP project's reference reader,
// twice: through the summary and indexes (McapIndexedReader), and record by
// record with every CRC checked (McapStreamReader). Each argument is
// FILE:MESSAGES:CHANNELS[:fields]; with "fields", every message of a
// ros2msg schema is decoded as Foxglove decodes it (@foxglove/rosmsg parses
// the definition, @foxglove/rosmsg2-serialization reads the CDR) and its
// fields checked against what mcap_samples.cpp wrote. A file whose figures
// differ, or that a reader refuses, fails the check (exit 1). Prints one
// JSON line per file.
import { McapIndexedReader, McapStreamReader } from "@mcap/core";
import { parse } from "@foxglove/rosmsg";
import { MessageReader } from "@foxglove/rosmsg2-serialization";
import { readFileSync } from "node:fs";
import lz4 from "lz4js";
import { decompress as zstd } from "fzstd";

const decompressHandlers = {
  lz4: (buffer, size) => lz4.decompress(buffer, Number(size)),
  zstd: (buffer, size) => zstd(buffer, new Uint8Array(Number(size))),
};

// The fields mcap_samples.cpp gave message `i` of each type, by its name.
const expected = {
  "described/msg/Pose": (i) => ({
    position: { x: i, y: 2 * i, z: -i },
    orientation: [0.5 * i, 0, 0, 1],
    frame: i % 7,
  }),
  "samples/msg/Reading": (i) => ({
    quality: i % 200,
    at: { x: 0.25 * i, y: 0, z: 3 },
    name: `r${i % 1000}`,
    values: Array.from({ length: i % 5 }, (_, k) => k + i),
    ok: i % 2 === 0,
  }),
};
const plain = (v) => (ArrayBuffer.isView(v) ? Array.from(v) : v);
const same = (a, b) => JSON.stringify(a, (k, v) => plain(v)) === JSON.stringify(b, (k, v) => plain(v));

let failed = false;
for (const arg of process.argv.slice(2)) {
  const [file, messages, channels, fields] = arg.split(":");
  const bytes = readFileSync(file);
  const readable = {
    size: async () => BigInt(bytes.length),
    read: async (offset, length) => bytes.subarray(Number(offset), Number(offset + length)),
  };
  const indexed = await McapIndexedReader.Initialize({ readable, decompressHandlers });
  let read = 0;
  let decoded = 0;
  let last = -1n;
  const readers = new Map();
  for await (const m of indexed.readMessages()) {
    if (m.logTime < last) throw new Error(`${file}: messages out of log_time order`);
    last = m.logTime;
    read++;
    if (fields !== "fields") continue;
    const channel = indexed.channelsById.get(m.channelId);
    const schema = indexed.schemasById.get(channel.schemaId);
    if (schema.encoding !== "ros2msg" || channel.messageEncoding !== "cdr") {
      console.error(`${file}: ${channel.topic} is ${schema.encoding}/${channel.messageEncoding}, not ros2msg/cdr`);
      failed = true;
      continue;
    }
    if (!readers.has(schema.id))
      readers.set(schema.id, new MessageReader(parse(new TextDecoder().decode(schema.data), { ros2: true })));
    const got = readers.get(schema.id).readMessage(m.data);
    const want = expected[schema.name]?.(m.sequence);
    if (!want || !same(got, want)) {
      console.error(`${file}: ${schema.name} message ${m.sequence} decoded as ${JSON.stringify(got, (k, v) => plain(v))}, ` +
                    `not ${JSON.stringify(want)}`);
      failed = true;
      break;
    }
    decoded++;
  }
  const stream = new McapStreamReader({ decompressHandlers, validateCrcs: true });
  stream.append(bytes);
  let streamed = 0;
  for (let record; (record = stream.nextRecord()); ) if (record.type === "Message") streamed++;
  const seen = {
    file,
    indexed_messages: read,
    statistics_messages: Number(indexed.statistics?.messageCount ?? -1n),
    streamed_messages: streamed,
    chunks: indexed.chunkIndexes.length,
    channels: indexed.channelsById.size,
    complete: stream.done(),
    decoded_messages: decoded,
  };
  console.log(JSON.stringify(seen));
  const want = Number(messages);
  if (read !== want || seen.statistics_messages !== want || streamed !== want || seen.channels !== Number(channels) ||
      !seen.complete || (fields === "fields" && decoded !== want)) {
    console.error(`${file}: expected ${want} messages on ${channels} channels`);
    failed = true;
  }
}
process.exit(failed ? 1 : 0);
