#include "seqloc/ros/mcap_writer.hpp"

#include <zlib.h>

#include <algorithm>
#include <cassert>
#include <limits>

#include <stdexcept>

namespace seqloc::ros {
namespace {

// The spec's opcodes (https://mcap.dev/spec#records).
enum Opcode : std::uint8_t {
  kHeader = 0x01,
  kFooter = 0x02,
  kSchema = 0x03,
  kChannel = 0x04,
  kMessage = 0x05,
  kChunk = 0x06,
  kMessageIndex = 0x07,
  kChunkIndex = 0x08,
  kStatistics = 0x0B,
  kMetadata = 0x0C,
  kMetadataIndex = 0x0D,
  kSummaryOffset = 0x0E,
  kDataEnd = 0x0F,
};

constexpr std::string_view kMagic{"\x89MCAP0\r\n", 8};

// A record's fields, little-endian as the spec has every integer.
class Fields {
 public:
  template <class T>
  Fields& integer(T v) {
    for (std::size_t i = 0; i < sizeof(T); ++i) bytes_.push_back(static_cast<char>((v >> (8 * i)) & 0xFF));
    return *this;
  }
  Fields& u8(std::uint8_t v) { return integer(v); }
  Fields& u16(std::uint16_t v) { return integer(v); }
  Fields& u32(std::uint32_t v) { return integer(v); }
  Fields& u64(std::uint64_t v) { return integer(v); }
  // String and Bytes: a uint32 length, then the bytes.
  Fields& string(std::string_view s) {
    u32(static_cast<std::uint32_t>(s.size()));
    bytes_.append(s);
    return *this;
  }
  // Map<string, string>: a uint32 byte length, then each key and value as strings.
  Fields& map(const McapMap& m) {
    Fields entries;
    for (const auto& [k, v] : m) entries.string(k).string(v);
    return string(entries.bytes());
  }
  Fields& raw(std::string_view s) {
    bytes_.append(s);
    return *this;
  }
  [[nodiscard]] const std::string& bytes() const { return bytes_; }

 private:
  std::string bytes_;
};

// <opcode><uint64 content length><content>
std::string record(Opcode op, const Fields& f) {
  Fields r;
  r.u8(op).u64(f.bytes().size()).raw(f.bytes());
  return r.bytes();
}

std::uint32_t crc32_of(std::string_view bytes, std::uint32_t crc = 0) {
  // zlib's crc32 is the CRC-32 (ISO-HDLC) the spec names; it takes at most uInt bytes at a time.
  while (!bytes.empty()) {
    const auto n = static_cast<uInt>(std::min<std::size_t>(bytes.size(), std::numeric_limits<uInt>::max()));
    crc = static_cast<std::uint32_t>(crc32(crc, reinterpret_cast<const Bytef*>(bytes.data()), n));
    bytes.remove_prefix(n);
  }
  return crc;
}

// Map<uint16, uint64>: a uint32 byte length, then the pairs.
Fields& id_count_map(Fields& f, const std::map<std::uint16_t, std::uint64_t>& m) {
  Fields entries;
  for (const auto& [k, v] : m) entries.u16(k).u64(v);
  return f.string(entries.bytes());
}

}  // namespace

McapWriter::McapWriter(std::string_view profile, std::string_view library, std::size_t chunk_bytes)
    : chunk_bytes_(std::max<std::size_t>(chunk_bytes, 1)) {
  file_.append(kMagic);
  file_ += record(kHeader, Fields().string(profile).string(library));
}

void McapWriter::check_open() const {
  if (finished_) throw std::logic_error("McapWriter: used after finish()");
}

std::uint16_t McapWriter::add_schema(std::string_view name, std::string_view encoding, std::string_view data) {
  check_open();
  close_chunk();  // schemas and channels stand in the data section before the messages that use them
  const auto id = static_cast<std::uint16_t>(schema_records_.size() + 1);  // 0 means "no schema"
  schema_records_.push_back(record(kSchema, Fields().u16(id).string(name).string(encoding).string(data)));
  file_ += schema_records_.back();
  return id;
}

std::uint16_t McapWriter::add_channel(std::uint16_t schema_id, std::string_view topic,
                                      std::string_view message_encoding, const McapMap& metadata) {
  check_open();
  if (schema_id == 0 || schema_id > schema_records_.size()) {
    throw std::logic_error("McapWriter: channel " + std::string(topic) + " names schema " + std::to_string(schema_id) +
                           ", which was not added");
  }
  close_chunk();
  const auto id = static_cast<std::uint16_t>(channel_records_.size());
  channel_records_.push_back(
      record(kChannel, Fields().u16(id).u16(schema_id).string(topic).string(message_encoding).map(metadata)));
  file_ += channel_records_.back();
  sequences_.push_back(0);
  channel_schema_.push_back(schema_id);
  return id;
}

void McapWriter::add_message(std::uint16_t channel_id, std::uint64_t log_time_ns, std::uint64_t publish_time_ns,
                             std::string_view data) {
  check_open();
  if (channel_id >= channel_records_.size()) {
    throw std::logic_error("McapWriter: message on channel " + std::to_string(channel_id) + ", which was not added");
  }
  if (chunk_.empty()) chunk_start_ns_ = chunk_end_ns_ = log_time_ns;
  chunk_start_ns_ = std::min(chunk_start_ns_, log_time_ns);
  chunk_end_ns_ = std::max(chunk_end_ns_, log_time_ns);
  if (messages_ == 0) start_ns_ = end_ns_ = log_time_ns;
  start_ns_ = std::min(start_ns_, log_time_ns);
  end_ns_ = std::max(end_ns_, log_time_ns);
  chunk_index_[channel_id].emplace_back(log_time_ns, chunk_.size());
  chunk_ += record(
      kMessage, Fields().u16(channel_id).u32(sequences_[channel_id]++).u64(log_time_ns).u64(publish_time_ns).raw(data));
  ++channel_counts_[channel_id];
  ++messages_;
  if (chunk_.size() >= chunk_bytes_) close_chunk();
}

void McapWriter::add_metadata(std::string_view name, const McapMap& metadata) {
  check_open();
  close_chunk();  // metadata records stand outside chunks
  const std::string r = record(kMetadata, Fields().string(name).map(metadata));
  metadata_.push_back({file_.size(), r.size(), std::string(name)});
  file_ += r;
}

std::uint64_t McapWriter::message_count(std::uint16_t channel_id) const {
  const auto it = channel_counts_.find(channel_id);
  return it == channel_counts_.end() ? 0 : it->second;
}

// The open chunk (uncompressed) and, after it, a message index per channel it holds.
void McapWriter::close_chunk() {
  if (chunk_.empty()) return;
  ChunkIndex index;
  index.start_ns = chunk_start_ns_;
  index.end_ns = chunk_end_ns_;
  index.offset = file_.size();
  index.records_bytes = chunk_.size();
  Fields chunk;
  chunk.u64(chunk_start_ns_).u64(chunk_end_ns_).u64(chunk_.size()).u32(crc32_of(chunk_)).string("");
  chunk.u64(chunk_.size()).raw(chunk_);  // the records field has a uint64 length
  file_ += record(kChunk, chunk);
  index.length = file_.size() - index.offset;
  const std::uint64_t indexes_start = file_.size();
  for (const auto& [channel, entries] : chunk_index_) {
    Fields pairs;
    for (const auto& [time, offset] : entries) pairs.u64(time).u64(offset);
    index.message_index_offsets[channel] = file_.size();
    file_ += record(kMessageIndex, Fields().u16(channel).string(pairs.bytes()));
  }
  index.message_index_length = file_.size() - indexes_start;
  chunks_.push_back(std::move(index));
  chunk_.clear();
  chunk_index_.clear();
}

std::string McapWriter::finish() {
  check_open();
  close_chunk();
  finished_ = true;
  file_ += record(kDataEnd, Fields().u32(crc32_of(file_)));

  // The summary: each group of records, and an offset record per group after them.
  const std::uint64_t summary_start = file_.size();
  std::vector<std::string> offsets;
  auto group = [&](Opcode op, const std::vector<std::string>& records) {
    if (records.empty()) return;
    const std::uint64_t start = file_.size();
    for (const auto& r : records) file_ += r;
    offsets.push_back(record(kSummaryOffset, Fields().u8(op).u64(start).u64(file_.size() - start)));
  };
  group(kSchema, schema_records_);
  group(kChannel, channel_records_);
  Fields stats;
  stats.u64(messages_)
      .u16(static_cast<std::uint16_t>(schema_records_.size()))
      .u32(static_cast<std::uint32_t>(channel_records_.size()))
      .u32(0)  // attachments
      .u32(static_cast<std::uint32_t>(metadata_.size()))
      .u32(static_cast<std::uint32_t>(chunks_.size()))
      .u64(start_ns_)
      .u64(end_ns_);
  std::map<std::uint16_t, std::uint64_t> counts;
  for (std::size_t c = 0; c < channel_records_.size(); ++c) {
    const auto id = static_cast<std::uint16_t>(c);
    counts[id] = message_count(id);
  }
  group(kStatistics, {record(kStatistics, id_count_map(stats, counts))});
  std::vector<std::string> chunk_records;
  for (const auto& c : chunks_) {
    Fields f;
    f.u64(c.start_ns).u64(c.end_ns).u64(c.offset).u64(c.length);
    id_count_map(f, c.message_index_offsets);
    f.u64(c.message_index_length).string("").u64(c.records_bytes).u64(c.records_bytes);
    chunk_records.push_back(record(kChunkIndex, f));
  }
  group(kChunkIndex, chunk_records);
  std::vector<std::string> metadata_records;
  for (const auto& m : metadata_) {
    metadata_records.push_back(record(kMetadataIndex, Fields().u64(m.offset).u64(m.length).string(m.name)));
  }
  group(kMetadataIndex, metadata_records);
  const std::uint64_t summary_offset_start = file_.size();
  for (const auto& o : offsets) file_ += o;

  // The footer's CRC covers the summary, the summary offsets and the footer up to the CRC itself.
  // Its record is written field by field: opcode, content length (two offsets and the CRC), then
  // the CRC of everything from the summary's start to here.
  file_ += Fields().u8(kFooter).u64(8 + 8 + 4).u64(summary_start).u64(summary_offset_start).bytes();
  file_ += Fields().u32(crc32_of(std::string_view(file_).substr(summary_start))).bytes();
  file_.append(kMagic);
  return std::move(file_);
}

}  // namespace seqloc::ros
