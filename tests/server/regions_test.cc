// Active regions: the config parser (every field validated, errors name the
// key), the occupied volume, and the events: once on entry, once on exit,
// never on noise.
#include <gtest/gtest.h>

#include <random>

#include "server/regions/regions.h"

namespace holo::regions {
namespace {

using protocol::RegionState;

const char* kConfig = R"(
cell_mm: 20
enter_litres: 0.4
exit_litres: 0.1
enter_frames: 2
exit_frames: 3
regions:
  - name: table
    box: {min: [0, 0, 0.8], max: [0.6, 0.4, 1.2]}
  - name: lamp
    sphere: {center: [1, -1, 1.8], radius: 0.25}
    enter_litres: 0.2
    exit_litres: 0.05
)";

RegionsConfig TableConfig() {
  auto c = ParseRegionsConfig(kConfig, "test.yaml");
  HOLO_CHECK(c.ok());
  return *c;
}

// A "hand": a 16 cm × 10 cm surface patch sampled every 5 mm, its near
// corner at `at`.
std::vector<Eigen::Vector3f> Hand(const Eigen::Vector3f& at) {
  std::vector<Eigen::Vector3f> p;
  for (int i = 0; i < 32; ++i)
    for (int j = 0; j < 20; ++j) p.push_back(at + Eigen::Vector3f(0.005f * i, 0.005f * j, 0.0f));
  return p;
}

TEST(RegionsConfig, ParsesBoxesSpheresAndOverrides) {
  const RegionsConfig c = TableConfig();
  EXPECT_FLOAT_EQ(c.cell_m, 0.02f);
  ASSERT_EQ(c.regions.size(), 2u);
  EXPECT_EQ(c.regions[0].name, "table");
  EXPECT_EQ(c.regions[0].shape, protocol::RegionShape::kBox);
  EXPECT_FLOAT_EQ(c.regions[0].max.z(), 1.2f);
  EXPECT_FLOAT_EQ(c.regions[0].enter_litres, 0.4f);  // the default
  EXPECT_EQ(c.regions[1].shape, protocol::RegionShape::kSphere);
  EXPECT_FLOAT_EQ(c.regions[1].radius, 0.25f);
  EXPECT_FLOAT_EQ(c.regions[1].enter_litres, 0.2f);  // its own
  EXPECT_TRUE(c.regions[1].Contains({1.1f, -1.1f, 1.9f}));
  EXPECT_FALSE(c.regions[1].Contains({1.2f, -1.2f, 1.95f}));  // in the cube, outside the ball
  // Defaults when only regions are given.
  auto d = ParseRegionsConfig("regions: [{name: a, box: {min: [0,0,0], max: [1,1,1]}}]", "d.yaml");
  ASSERT_TRUE(d.ok()) << d.status().message();
  EXPECT_FLOAT_EQ(d->regions[0].enter_litres, RegionsConfig{}.enter_litres);
}

TEST(RegionsConfig, TheExampleConfigLoads) {
  auto c = LoadRegionsConfig(std::string(HOLO_SOURCE_DIR) + "/config/regions/studio-example.yaml");
  ASSERT_TRUE(c.ok()) << c.status().message();
  ASSERT_EQ(c->regions.size(), 3u);
  EXPECT_EQ(c->regions[1].name, "ball path");
  EXPECT_EQ(c->regions[1].shape, protocol::RegionShape::kSphere);
}

TEST(RegionsConfig, ErrorsNameTheFileKeyAndValue) {
  const std::string box = "box: {min: [0,0,0], max: [1,1,1]}";
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"[1, 2", "not valid YAML"},
      {"- a\n- b", "top level"},
      {"cell_mm: 20", "regions: missing"},
      {"regions: {}", "regions: must be a list"},
      {"regions: []", "at least one region"},
      {"regoins: []", "regoins: unknown key"},
      {"cell_mm: 0.5\nregions: [{name: a, " + box + "}]", "cell_mm: must be 2..1000, got 0.5"},
      {"cell_mm: lots\nregions: [{name: a, " + box + "}]", "cell_mm: must be a number, got 'lots'"},
      {"cell_mm: .nan\nregions: [{name: a, " + box + "}]", "cell_mm: must be a finite number"},
      {"enter_frames: 0\nregions: [{name: a, " + box + "}]", "enter_frames: must be 1..300"},
      {"exit_frames: 2.5\nregions: [{name: a, " + box + "}]", "exit_frames: must be a whole number"},
      {"min_points_per_cell: 0\nregions: [{name: a, " + box + "}]", "min_points_per_cell"},
      {"regions: [{" + box + "}]", "regions[0].name: missing"},
      {"regions: [{name: '', " + box + "}]", "regions[0].name: must be 1..64 bytes"},
      {"regions: [{name: [x], " + box + "}]", "regions[0].name: must be a string"},
      {"regions: [{name: a, " + box + "}, {name: a, " + box + "}]", "regions[1].name: 'a' is used twice"},
      {"regions: [{name: a}]", "regions[0]: needs exactly one of 'box' or 'sphere'"},
      {"regions: [{name: a, " + box + ", sphere: {center: [0,0,0], radius: 1}}]", "exactly one"},
      {"regions: [{name: a, box: {min: [0,0,0], max: [1,0,1]}}]", "regions[0].box.max: must exceed min"},
      {"regions: [{name: a, box: {min: [0,0], max: [1,1,1]}}]", "regions[0].box.min: must be a list of 3"},
      {"regions: [{name: a, box: {min: [0,x,0], max: [1,1,1]}}]", "regions[0].box.min[1]: must be a number"},
      {"regions: [{name: a, box: {min: [0,0,0]}}]", "regions[0].box.max: missing"},
      {"regions: [{name: a, box: {min: [0,0,0], max: [1,1,1], mid: 1}}]", "regions[0].box.mid: unknown key"},
      {"regions: [{name: a, box: {min: [0,0,0], max: [1e9,1,1]}}]", "within ±1000 m"},
      {"regions: [{name: a, sphere: {center: [0,0,0]}}]", "regions[0].sphere.radius: missing"},
      {"regions: [{name: a, sphere: {center: [0,0,0], radius: -1}}]", "regions[0].sphere.radius: must be in (0, 100]"},
      {"regions: [{name: a, " + box + ", exit_litres: 2}]", "regions[0].exit_litres: must be >= 0 and below"},
      {"regions: [{name: a, " + box + ", enter_litres: 0}]", "regions[0].enter_litres: must be > 0"},
      {"regions: [{name: a, " + box + ", colour: red}]", "regions[0].colour: unknown key"},
      {"regions: [7]", "regions[0]: must be a map"},
  };
  for (const auto& [text, want] : cases) {
    auto c = ParseRegionsConfig(text, "site-regions.yaml");
    ASSERT_FALSE(c.ok()) << text;
    EXPECT_NE(c.status().message().find(want), std::string::npos) << text << "\n -> " << c.status().message();
    EXPECT_NE(c.status().message().find("site-regions.yaml"), std::string::npos) << c.status().message();
  }
  std::string many = "regions:\n";
  for (int i = 0; i < 65; ++i) many += "  - {name: r" + std::to_string(i) + ", " + box + "}\n";
  auto c = ParseRegionsConfig(many, "many.yaml");
  ASSERT_FALSE(c.ok());
  EXPECT_NE(c.status().message().find("at most 64"), std::string::npos);
  EXPECT_FALSE(LoadRegionsConfig("/nonexistent/regions.yaml").ok());
}

TEST(RegionOccupancy, CountsCellsWithEnoughPointsInsideTheShape) {
  const RegionsConfig c = TableConfig();
  std::vector<uint64_t> scratch;
  // The 16 × 10 cm hand lies flat inside the table box: 8 × 5 cells of 2 cm,
  // 8 cm³ each (corners 1 mm off the cell grid, so rounding cannot split a row).
  const auto hand = Hand({0.101f, 0.101f, 1.001f});
  EXPECT_NEAR(OccupiedLitres(c.regions[0], hand, c.cell_m, 1, &scratch), 8 * 5 * 8e-3f, 1e-4f);
  // Outside: nothing. Half in (x from 0.521 to 0.676, the box ends at 0.6): half the cells.
  EXPECT_EQ(OccupiedLitres(c.regions[0], Hand({0.1f, 0.1f, 1.3f}), c.cell_m, 1, &scratch), 0.0f);
  EXPECT_NEAR(OccupiedLitres(c.regions[0], Hand({0.521f, 0.101f, 1.001f}), c.cell_m, 1, &scratch), 4 * 5 * 8e-3f,
              1e-4f);
  // Scattered single points fill no cell at min_points_per_cell 2.
  std::vector<Eigen::Vector3f> specks;
  for (int i = 0; i < 20; ++i) specks.push_back({0.01f + 0.029f * i, 0.2f, 0.81f + 0.019f * i});
  EXPECT_EQ(OccupiedLitres(c.regions[0], specks, c.cell_m, 2, &scratch), 0.0f);
  EXPECT_GT(OccupiedLitres(c.regions[0], specks, c.cell_m, 1, &scratch), 0.0f);
}

// The test of the issue: events fire once on entry and once on exit.
TEST(RegionTracker, FiresOnceOnEntryAndOnceOnExit) {
  RegionTracker t(TableConfig());
  std::vector<RegionState> table;
  int64_t enter_frame = -1, leave_frame = -1;
  for (int64_t f = 0; f < 60; ++f) {
    // Out for 10 frames, in for 30, out again; the hand trembles by ±4 mm.
    const float tremble = 0.004f * static_cast<float>((f * 7) % 3 - 1);
    const Eigen::Vector3f at = f >= 10 && f < 40 ? Eigen::Vector3f(0.2f, 0.1f, 1.0f + tremble)
                                                 : Eigen::Vector3f(0.2f, 0.1f, 1.4f + tremble);
    const protocol::Regions& r = t.Update(f, Hand(at));
    ASSERT_EQ(r.regions.size(), 2u);
    EXPECT_EQ(r.frame_index, f);
    EXPECT_EQ(r.regions[1].state, RegionState::kEmpty);  // the lamp is never touched
    table.push_back(r.regions[0].state);
    if (r.regions[0].state == RegionState::kEnter) enter_frame = f;
    if (r.regions[0].state == RegionState::kLeave) leave_frame = f;
  }
  EXPECT_EQ(std::count(table.begin(), table.end(), RegionState::kEnter), 1);
  EXPECT_EQ(std::count(table.begin(), table.end(), RegionState::kLeave), 1);
  EXPECT_EQ(enter_frame, 11);  // the second frame in a row inside (enter_frames 2)
  EXPECT_EQ(leave_frame, 42);  // the third frame in a row outside (exit_frames 3)
  for (int64_t f = 12; f < 42; ++f) EXPECT_EQ(table[f], RegionState::kStay) << f;
  EXPECT_EQ(t.events(), 2);
}

// A still scene with noise: a body resting against the box (points jitter
// across its face), specks of depth noise everywhere, and single-frame
// blips of a few centimetres. Nothing fires.
TEST(RegionTracker, NoEventsOnNoise) {
  RegionTracker t(TableConfig());
  std::mt19937 rng(7);
  std::normal_distribution<float> jitter(0.0f, 0.004f);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  for (int64_t f = 0; f < 600; ++f) {
    std::vector<Eigen::Vector3f> pts;
    // A vertical "torso" surface 5 mm outside the box's +x face, jittering across it.
    for (int i = 0; i < 40; ++i)
      for (int j = 0; j < 40; ++j)
        pts.push_back({0.605f + jitter(rng), -0.1f + 0.015f * i, 0.7f + 0.015f * j});
    // 200 specks anywhere around (depth noise, flying pixels).
    for (int k = 0; k < 200; ++k) pts.push_back({-0.5f + 2.0f * u(rng), -0.5f + 1.5f * u(rng), 0.5f + u(rng)});
    // Every 50 frames a one-frame blip (a 6 × 6 cm fragment) inside the box.
    if (f % 50 == 25)
      for (int i = 0; i < 12; ++i)
        for (int j = 0; j < 12; ++j) pts.push_back({0.2f + 0.005f * i, 0.2f + 0.005f * j, 1.0f});
    const protocol::Regions& r = t.Update(f, pts);
    for (const auto& g : r.regions) ASSERT_EQ(g.state, RegionState::kEmpty) << "frame " << f << " " << g.name;
  }
  EXPECT_EQ(t.events(), 0);
}

// Occupied, then the volume wavers between exit and enter thresholds: it stays
// occupied (hysteresis), and a single frame below exit does not end it.
TEST(RegionTracker, HysteresisHoldsBetweenThresholds) {
  RegionTracker t(TableConfig());
  std::vector<uint64_t> scratch;
  const auto full = Hand({0.1f, 0.1f, 1.0f});  // 0.32 L: below enter (0.4 L)
  std::vector<Eigen::Vector3f> big = full;
  for (const auto& p : Hand({0.1f, 0.1f, 1.05f})) big.push_back(p);  // two layers: 0.64 L
  const RegionsConfig& c = t.config();
  ASSERT_GE(OccupiedLitres(c.regions[0], big, c.cell_m, c.min_points_per_cell, &scratch), 0.4f);
  // A small patch: between exit (0.1) and enter (0.4).
  std::vector<Eigen::Vector3f> small(full.begin(), full.begin() + 20 * 12);  // 6 × 10 cm
  const float v_small = OccupiedLitres(c.regions[0], small, c.cell_m, c.min_points_per_cell, &scratch);
  ASSERT_GT(v_small, 0.1f);
  ASSERT_LT(v_small, 0.4f);
  const std::vector<Eigen::Vector3f> none;
  int events = 0;
  for (int64_t f = 0; f < 100; ++f) {
    const std::vector<Eigen::Vector3f>* pts = f < 5 ? &big : &small;
    if (f == 60 || f == 61) pts = &none;  // two frames empty: fewer than exit_frames
    const auto& r = t.Update(f, *pts);
    if (r.regions[0].state == RegionState::kEnter || r.regions[0].state == RegionState::kLeave) ++events;
  }
  EXPECT_EQ(events, 1);  // entered once, never left
}

}  // namespace
}  // namespace holo::regions
