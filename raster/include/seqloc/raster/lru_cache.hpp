#pragma once
// A least-recently-used cache bounded by a total cost (entries, or bytes): the decoded tiles of a
// CacheReader and the encoded responses of the tile server. Not synchronized: callers hold
// their own lock around it.

#include <cstddef>
#include <functional>
#include <list>
#include <unordered_map>
#include <utility>

namespace seqloc::raster {

template <class Key, class Value, class Hash = std::hash<Key>>
class LruCache {
 public:
  using Cost = std::function<std::size_t(const Value&)>;

  /// Holds entries up to a total cost of `capacity`; `cost` gives an entry's (1 each when empty,
  /// so that the capacity counts entries).
  explicit LruCache(std::size_t capacity, Cost cost = {}) : capacity_(capacity), cost_(std::move(cost)) {}

  /// The value under `key`, made the most recent; null when absent. Valid until the next insert.
  [[nodiscard]] const Value* find(const Key& key) {
    const auto it = index_.find(key);
    if (it == index_.end()) return nullptr;
    entries_.splice(entries_.begin(), entries_, it->second);
    return &it->second->second;
  }
  [[nodiscard]] bool contains(const Key& key) const { return index_.count(key) != 0; }

  /// The value under `key` without making it the most recent; null when absent.
  [[nodiscard]] const Value* peek(const Key& key) const {
    const auto it = index_.find(key);
    return it == index_.end() ? nullptr : &it->second->second;
  }

  /// Adds `value` under `key` as the most recent entry unless the key is there already (then
  /// nothing changes), and drops the least recent entries while the total cost exceeds the
  /// capacity (possibly the new one itself).
  void insert(const Key& key, Value value) {
    if (index_.count(key) != 0) return;
    entries_.emplace_front(key, std::move(value));
    index_.emplace(key, entries_.begin());
    total_ += cost_of(entries_.front().second);
    while (total_ > capacity_ && !entries_.empty()) {
      total_ -= cost_of(entries_.back().second);
      index_.erase(entries_.back().first);
      entries_.pop_back();
    }
  }

  [[nodiscard]] std::size_t size() const { return entries_.size(); }
  [[nodiscard]] std::size_t total_cost() const { return total_; }

 private:
  [[nodiscard]] std::size_t cost_of(const Value& value) const { return cost_ ? cost_(value) : 1; }

  std::size_t capacity_;
  Cost cost_;
  std::size_t total_ = 0;
  std::list<std::pair<Key, Value>> entries_;  ///< most recent first
  std::unordered_map<Key, typename std::list<std::pair<Key, Value>>::iterator, Hash> index_;
};

}  // namespace seqloc::raster
