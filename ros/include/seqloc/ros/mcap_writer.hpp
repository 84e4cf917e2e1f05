#pragma once
// A writer of MCAP files (https://mcap.dev/spec, major version 0), small and complete for what
// seqloc records: schemas, channels, messages in uncompressed chunks with their message indexes,
// metadata records, and a summary section (schemas, channels, statistics, chunk and metadata
// indexes, summary offsets) so that readers seek by time and topic instead of scanning. Every
// CRC the format has is filled in (data section, each chunk's records, the summary).
//
// The file is built in memory and returned whole by finish(): a route's bag is a few megabytes,
// and the caller writes it atomically (core::write_file), so no half-written bag is ever left.

#include <cstddef>
#include <cstdint>
#include <map>
#include <string>
#include <string_view>
#include <vector>

namespace seqloc::ros {

/// A record's string -> string map (Channel metadata, Metadata records), written in key order.
using McapMap = std::map<std::string, std::string>;

class McapWriter {
 public:
  /// `profile`: the header's profile ("ros2" for ROS 2 bags); `library`: who wrote the file.
  /// Messages go into chunks of about `chunk_bytes` uncompressed bytes each.
  McapWriter(std::string_view profile, std::string_view library, std::size_t chunk_bytes = std::size_t{1} << 20);

  /// Adds a schema (`encoding` e.g. "ros2msg"; `data` its definition text); returns its id (from 1).
  std::uint16_t add_schema(std::string_view name, std::string_view encoding, std::string_view data);
  /// Adds a channel on a schema added before; returns its id (from 0).
  std::uint16_t add_channel(std::uint16_t schema_id, std::string_view topic, std::string_view message_encoding,
                            const McapMap& metadata = {});
  /// Adds a message on a channel added before; times in nanoseconds. Messages need not come in
  /// time order (the indexes record each one's time).
  void add_message(std::uint16_t channel_id, std::uint64_t log_time_ns, std::uint64_t publish_time_ns,
                   std::string_view data);
  /// Adds a Metadata record (name and key-value pairs), indexed in the summary.
  void add_metadata(std::string_view name, const McapMap& metadata);

  /// Messages added so far on a channel.
  [[nodiscard]] std::uint64_t message_count(std::uint16_t channel_id) const;

  /// Ends the data section, writes the summary, the footer and the closing magic, and returns the
  /// whole file. The writer takes nothing more after it.
  [[nodiscard]] std::string finish();

 private:
  struct ChunkIndex {
    std::uint64_t start_ns = 0, end_ns = 0, offset = 0, length = 0;
    std::map<std::uint16_t, std::uint64_t> message_index_offsets;
    std::uint64_t message_index_length = 0, records_bytes = 0;
  };
  struct MetadataIndex {
    std::uint64_t offset = 0, length = 0;
    std::string name;
  };
  void close_chunk();
  void check_open() const;

  std::string file_;
  std::size_t chunk_bytes_;
  // The open chunk: its records, their times and each channel's (time, offset) pairs.
  std::string chunk_;
  std::uint64_t chunk_start_ns_ = 0, chunk_end_ns_ = 0;
  std::map<std::uint16_t, std::vector<std::pair<std::uint64_t, std::uint64_t>>> chunk_index_;
  // What the summary repeats and indexes.
  std::vector<std::string> schema_records_, channel_records_;
  std::vector<std::uint32_t> sequences_;  // per channel: the next message's sequence number
  std::vector<std::uint16_t> channel_schema_;
  std::map<std::uint16_t, std::uint64_t> channel_counts_;
  std::vector<ChunkIndex> chunks_;
  std::vector<MetadataIndex> metadata_;
  std::uint64_t messages_ = 0, start_ns_ = 0, end_ns_ = 0;
  bool finished_ = false;
};

}  // namespace seqloc::ros
