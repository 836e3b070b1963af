// Reads recordings with @mcap/core, the MCAP project's reference reader,
// twice: through the summary and indexes (McapIndexedReader), and record by
// record with every CRC checked (McapStreamReader). Each argument is
// FILE:MESSAGES:CHANNELS; a file whose figures differ, or that either
// reader refuses, fails the check (exit 1). Prints one JSON line per file.
import { McapIndexedReader, McapStreamReader } from "@mcap/core";
import { readFileSync } from "node:fs";
import lz4 from "lz4js";
import { decompress as zstd } from "fzstd";

const decompressHandlers = {
  lz4: (buffer, size) => lz4.decompress(buffer, Number(size)),
  zstd: (buffer, size) => zstd(buffer, new Uint8Array(Number(size))),
};

let failed = false;
for (const arg of process.argv.slice(2)) {
  const [file, messages, channels] = arg.split(":");
  const bytes = readFileSync(file);
  const readable = {
    size: async () => BigInt(bytes.length),
    read: async (offset, length) => bytes.subarray(Number(offset), Number(offset + length)),
  };
  const indexed = await McapIndexedReader.Initialize({ readable, decompressHandlers });
  let read = 0;
  let last = -1n;
  for await (const m of indexed.readMessages()) {
    if (m.logTime < last) throw new Error(`${file}: messages out of log_time order`);
    last = m.logTime;
    read++;
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
  };
  console.log(JSON.stringify(seen));
  const want = Number(messages);
  if (read !== want || seen.statistics_messages !== want || streamed !== want || seen.channels !== Number(channels) ||
      !seen.complete) {
    console.error(`${file}: expected ${want} messages on ${channels} channels`);
    failed = true;
  }
}
process.exit(failed ? 1 : 0);
