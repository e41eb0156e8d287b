#include <gtest/gtest.h>

#include "cellsight/localization/instance_names.hpp"

using cellsight::assignInstanceNames;
using cellsight::NamedInstance;

TEST(InstanceNames, NewPartsTakeTheSmallestFreeIndexOfTheirModel) {
  const auto names = assignInstanceNames({}, {{"housing", "", {0, 0, 0}}, {"blade", "", {1, 0, 0}},
                                              {"housing", "", {2, 0, 0}}});
  EXPECT_EQ(names, (std::vector<std::string>{"object/housing_0", "object/blade_0", "object/housing_1"}));
}

TEST(InstanceNames, APartSeenAgainNearbyKeepsItsName) {
  const std::vector<NamedInstance> prev = {{"housing", "object/housing_0", {0, 0, 0}},
                                           {"housing", "object/housing_1", {0.3, 0, 0}}};
  // listed in the other order, each moved 5 mm: the names follow the parts, not the order
  const auto names = assignInstanceNames(prev, {{"housing", "", {0.305, 0, 0}}, {"housing", "", {0.005, 0, 0}}});
  EXPECT_EQ(names, (std::vector<std::string>{"object/housing_1", "object/housing_0"}));
}

TEST(InstanceNames, FarMovesAndOtherModelsGetNewNames) {
  const std::vector<NamedInstance> prev = {{"housing", "object/housing_0", {0, 0, 0}}};
  const auto names = assignInstanceNames(prev, {{"blade", "", {0, 0, 0}}, {"housing", "", {0.2, 0, 0}}});
  // housing_0 is free again (its part left), so the far housing may take it; the blade is blade_0
  EXPECT_EQ(names[0], "object/blade_0");
  EXPECT_EQ(names[1], "object/housing_0");
  const auto kept = assignInstanceNames(prev, {{"housing", "", {0.2, 0, 0}}, {"housing", "", {0.01, 0, 0}}});
  EXPECT_EQ(kept[1], "object/housing_0");
  EXPECT_EQ(kept[0], "object/housing_1");
}
