// Names of located parts that persist across scans: object/<model>_<k>. A part found again near
// where an instance of its model was last seen keeps that instance's name; a new one takes the
// smallest free k of its model. So `object/housing_0` names the same housing scan after scan.
#pragma once
#include <Eigen/Core>
#include <string>
#include <vector>

namespace cellsight {

struct NamedInstance {
  std::string model;
  std::string name;  ///< e.g. object/housing_0
  Eigen::Vector3d position = Eigen::Vector3d::Zero();
};

/// Names for `current` (model, position) given the instances of the previous scan. Pairs are made
/// per model, closest first, up to `max_move` metres apart. Returns one name per current entry.
std::vector<std::string> assignInstanceNames(const std::vector<NamedInstance>& previous,
                                             const std::vector<NamedInstance>& current, double max_move = 0.05,
                                             const std::string& prefix = "object/");

}  // namespace cellsight
