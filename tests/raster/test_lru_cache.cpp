// LruCache against a brute-force model: a list searched linearly, most recent first, trimmed
// from the back while over capacity.
#include <algorithm>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "seqloc/raster/lru_cache.hpp"

namespace seqloc::raster {
namespace {

struct Model {
  std::size_t capacity;
  bool by_length;
  std::vector<std::pair<int, std::string>> entries;  // most recent first

  [[nodiscard]] std::size_t cost(const std::string& v) const { return by_length ? v.size() : 1; }
  const std::string* find(int key) {
    const auto it = std::find_if(entries.begin(), entries.end(), [&](const auto& e) { return e.first == key; });
    if (it == entries.end()) return nullptr;
    std::rotate(entries.begin(), it, it + 1);
    return &entries.front().second;
  }
  void insert(int key, const std::string& value) {
    if (std::any_of(entries.begin(), entries.end(), [&](const auto& e) { return e.first == key; })) return;
    entries.insert(entries.begin(), {key, value});
    auto total = [&] {
      std::size_t t = 0;
      for (const auto& e : entries) t += cost(e.second);
      return t;
    };
    while (total() > capacity && !entries.empty()) entries.pop_back();
  }
};

TEST(LruCache, MatchesABruteForceModelByCountAndByCost) {
  for (const bool by_length : {false, true}) {
    const std::size_t capacity = by_length ? 40 : 5;
    LruCache<int, std::string>::Cost cost;
    if (by_length) cost = [](const std::string& v) { return v.size(); };
    LruCache<int, std::string> cache(capacity, cost);
    Model model{capacity, by_length, {}};
    std::mt19937 rng(11);
    for (int step = 0; step < 20000; ++step) {
      const int key = static_cast<int>(rng() % 12);
      if (rng() % 2) {
        const std::string* want = model.find(key);
        const std::string* got = cache.find(key);
        ASSERT_EQ(got != nullptr, want != nullptr) << "step " << step;
        if (want) {
          ASSERT_EQ(*got, *want) << "step " << step;
        }
      } else {
        const std::string value(rng() % 25, static_cast<char>('a' + key));  // up to 24 bytes; 0 costs nothing
        model.insert(key, value);
        cache.insert(key, value);
      }
      ASSERT_EQ(cache.size(), model.entries.size()) << "step " << step;
      std::size_t total = 0;
      for (const auto& e : model.entries) {
        total += model.cost(e.second);
        ASSERT_TRUE(cache.contains(e.first)) << "step " << step;
        ASSERT_EQ(*cache.peek(e.first), e.second);
      }
      ASSERT_EQ(cache.total_cost(), total) << "step " << step;
    }
  }
}

}  // namespace
}  // namespace seqloc::raster
