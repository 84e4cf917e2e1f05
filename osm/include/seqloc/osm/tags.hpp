#pragma once
// A read-only view of an OSM element's tags, independent of libosmium so that the classifier can
// be tested from plain tables.

#include <initializer_list>
#include <string_view>
#include <utility>
#include <vector>

namespace seqloc::osm {

class TagView {
 public:
  using Tag = std::pair<std::string_view, std::string_view>;

  TagView() = default;
  TagView(std::initializer_list<Tag> tags) : tags_(tags) {}
  explicit TagView(std::vector<Tag> tags) : tags_(std::move(tags)) {}

  void add(std::string_view key, std::string_view value) { tags_.emplace_back(key, value); }

  /// The value of `key`, or nullptr when the element has no such tag.
  [[nodiscard]] const std::string_view* find(std::string_view key) const {
    for (const auto& tag : tags_) {
      if (tag.first == key) return &tag.second;
    }
    return nullptr;
  }
  [[nodiscard]] bool has(std::string_view key) const { return find(key) != nullptr; }
  [[nodiscard]] bool empty() const { return tags_.empty(); }
  [[nodiscard]] const std::vector<Tag>& tags() const { return tags_; }

 private:
  std::vector<Tag> tags_;
};

}  // namespace seqloc::osm
