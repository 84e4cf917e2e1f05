#include "seqloc/osm/multipolygon.hpp"

#include <utility>

namespace seqloc::osm {
namespace {

bool is_closed(const NodeChain& chain) { return chain.size() >= 2 && chain.front().id == chain.back().id; }

// OrienterNet's try_to_glue: the four ways two chains can share an endpoint. Returns false and
// leaves `chain` alone when they share none.
bool try_to_glue(NodeChain& chain, const NodeChain& other) {
  NodeChain glued;
  glued.reserve(chain.size() + other.size() - 1);
  if (chain.front().id == other.front().id) {
    glued.assign(other.rbegin(), other.rend() - 1);  // other reversed, without its first node
    glued.insert(glued.end(), chain.begin(), chain.end());
  } else if (chain.front().id == other.back().id) {
    glued.assign(other.begin(), other.end() - 1);
    glued.insert(glued.end(), chain.begin(), chain.end());
  } else if (chain.back().id == other.back().id) {
    glued = chain;
    glued.insert(glued.end(), other.rbegin() + 1, other.rend());
  } else if (chain.back().id == other.front().id) {
    glued = chain;
    glued.insert(glued.end(), other.begin() + 1, other.end());
  } else {
    return false;
  }
  chain = std::move(glued);
  return true;
}

}  // namespace

GluedRings glue_rings(std::vector<NodeChain> ways) {
  GluedRings out;
  std::vector<NodeChain> open;
  for (auto& way : ways) {
    if (way.size() < 2) continue;
    if (is_closed(way)) {
      out.rings.push_back(std::move(way));
    } else {
      open.push_back(std::move(way));
    }
  }
  std::vector<bool> used(open.size(), false);
  for (std::size_t i = 0; i < open.size(); ++i) {
    if (used[i]) continue;
    used[i] = true;
    NodeChain chain = std::move(open[i]);
    bool grew = true;
    while (grew && !is_closed(chain)) {
      grew = false;
      for (std::size_t j = i + 1; j < open.size(); ++j) {
        if (!used[j] && try_to_glue(chain, open[j])) {
          used[j] = true;
          grew = true;
          break;
        }
      }
    }
    if (is_closed(chain)) {
      out.rings.push_back(std::move(chain));
    } else {
      ++out.open_chains;
    }
  }
  return out;
}

std::vector<GeoPoint> ring_points(const NodeChain& ring) {
  std::vector<GeoPoint> points;
  points.reserve(ring.size());
  for (const auto& node : ring) {
    if (node.where) points.push_back(*node.where);
  }
  if (points.size() < 3) points.clear();
  return points;
}

}  // namespace seqloc::osm
