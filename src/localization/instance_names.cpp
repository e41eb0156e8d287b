#include "cellsight/localization/instance_names.hpp"

#include <algorithm>
#include <set>
#include <tuple>

namespace cellsight {

std::vector<std::string> assignInstanceNames(const std::vector<NamedInstance>& previous,
                                             const std::vector<NamedInstance>& current, double max_move,
                                             const std::string& prefix) {
  std::vector<std::string> names(current.size());
  // every (distance, previous, current) pair of one model within reach, closest first
  std::vector<std::tuple<double, size_t, size_t>> pairs;
  for (size_t p = 0; p < previous.size(); ++p) {
    for (size_t c = 0; c < current.size(); ++c) {
      if (previous[p].model != current[c].model) continue;
      const double d = (previous[p].position - current[c].position).norm();
      if (d <= max_move) pairs.emplace_back(d, p, c);
    }
  }
  std::sort(pairs.begin(), pairs.end());
  std::vector<bool> prev_used(previous.size(), false);
  std::set<std::string> taken;
  for (const auto& [d, p, c] : pairs) {
    if (prev_used[p] || !names[c].empty()) continue;
    prev_used[p] = true;
    names[c] = previous[p].name;
    taken.insert(names[c]);
  }
  for (size_t c = 0; c < current.size(); ++c) {
    if (!names[c].empty()) continue;
    for (int k = 0;; ++k) {
      const std::string n = prefix + current[c].model + "_" + std::to_string(k);
      if (taken.count(n)) continue;
      names[c] = n;
      taken.insert(n);
      break;
    }
  }
  return names;
}

}  // namespace cellsight
