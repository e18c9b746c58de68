// Active regions: named boxes and spheres in the site's world frame that
// fire an event when the reconstruction enters or leaves them (the "active
// regions" of the real-time visual-hull systems: a body touching a virtual
// object). docs/regions.md describes the config file and the figures.
//
// Occupancy of a region in one frame = the volume of the grid cells (edge
// `cell_mm`, grid anchored at the region's bounding-box minimum) that hold at
// least `min_points_per_cell` points of the reconstruction inside the
// region: the site's mesh vertices (fused TSDF or visual hull). A lone
// speck gives one point, so it fills no cell; a hand fills dozens.
//
// Events, per region, with hysteresis and frame debounce so that noise on
// the boundary fires nothing:
//   empty → occupied when the volume is ≥ `enter_litres` for `enter_frames`
//            frames in a row (state kEnter in that frame, once);
//   occupied → empty when the volume is < `exit_litres` for `exit_frames`
//            frames in a row (state kLeave in that frame, once);
//   kStay / kEmpty in every other frame.
// exit_litres < enter_litres: a volume wavering between the two changes
// nothing.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "common/status.h"
#include "protocol/messages.h"

namespace holo::regions {

struct RegionSpec {
  std::string name;  // 1..64 bytes, unique
  protocol::RegionShape shape = protocol::RegionShape::kBox;
  // Box: min and max corner; sphere: `min` is the centre, `radius` its radius (metres).
  Eigen::Vector3f min = Eigen::Vector3f::Zero();
  Eigen::Vector3f max = Eigen::Vector3f::Zero();
  float radius = 0;
  // Thresholds of this region (the config's defaults unless the region sets its own).
  float enter_litres = 0;
  float exit_litres = 0;
  bool Contains(const Eigen::Vector3f& p) const;
  // Axis-aligned bounds (the box itself, or the sphere's cube).
  Eigen::Vector3f BoundsMin() const;
  Eigen::Vector3f BoundsMax() const;
};

struct RegionsConfig {
  // Occupancy grid cell edge, metres. 30 mm: the studio's streamed mesh has a
  // vertex every ~15 mm, so a covered cell holds several.
  float cell_m = 0.03f;
  // Points a cell needs to count as occupied (1 = any point).
  int min_points_per_cell = 2;
  // Defaults of every region's thresholds, litres (1 L = 37 cells of 30 mm).
  float enter_litres = 0.5f;
  float exit_litres = 0.15f;
  // Frames in a row above enter (below exit) before the event fires.
  int enter_frames = 2;
  int exit_frames = 3;
  std::vector<RegionSpec> regions;
  // InvalidArgument naming the field ("regions[1].box.max: must exceed min on every axis").
  Status Check() const;
};

// Parses a regions config (YAML, docs/regions.md). Errors name the file
// (`source`), the key and the value. Safe on untrusted text.
StatusOr<RegionsConfig> ParseRegionsConfig(const std::string& text, const std::string& source);
StatusOr<RegionsConfig> LoadRegionsConfig(const std::string& path);

// Occupied volume of `region` by `points`, litres (see the header comment).
// `scratch` is reused between calls.
float OccupiedLitres(const RegionSpec& region, std::span<const Eigen::Vector3f> points, float cell_m,
                     int min_points_per_cell, std::vector<uint64_t>* scratch);

// Per-region state machines over a stream of frames. Not thread-safe.
class RegionTracker {
 public:
  // `config` must pass Check (HOLO_CHECK).
  explicit RegionTracker(RegionsConfig config);
  RegionTracker(const RegionTracker&) = delete;
  RegionTracker& operator=(const RegionTracker&) = delete;

  // The report of frame `frame_index` (≥ 0) given the reconstruction's
  // points (world, metres): every region with its state and volume. The
  // reference is valid until the next call.
  const protocol::Regions& Update(int64_t frame_index, std::span<const Eigen::Vector3f> points);

  const RegionsConfig& config() const { return config_; }
  // Events fired so far (kEnter + kLeave states reported).
  int64_t events() const { return events_; }

 private:
  struct Track {
    bool occupied = false;
    int run = 0;  // frames in a row past the threshold that would change `occupied`
  };
  RegionsConfig config_;
  std::vector<Track> tracks_;
  protocol::Regions report_;
  std::vector<uint64_t> scratch_;
  int64_t events_ = 0;
};

}  // namespace holo::regions
