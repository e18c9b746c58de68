// Active regions in the viewer: each region the site reports (PROTOCOL.md §4
// Regions) drawn in the remote world — a box as its 12 edges, a sphere as
// three great circles — grey-blue while empty; while occupied in bright
// orange with translucent orange faces (boxes) so that the highlight reads
// at a glance. Edges are depth-tested against the scene already drawn, so
// the person occludes the parts of a region behind them.
#pragma once

#include <memory>
#include <vector>

#include <Eigen/Core>

#include "client/render/renderer.h"
#include "common/camera.h"
#include "common/status.h"
#include "protocol/messages.h"

namespace holo::render {

class RegionBoxes {
 public:
  ~RegionBoxes();
  // Needs a current 3.3 core context.
  static StatusOr<std::unique_ptr<RegionBoxes>> Create();
  RegionBoxes(const RegionBoxes&) = delete;
  RegionBoxes& operator=(const RegionBoxes&) = delete;

  // Draws `regions` (remote world coordinates, placed by `local_from_remote`
  // as the remote mesh is) into `vp` of the bound framebuffer as seen by
  // `camera`. A region is highlighted when its state is kEnter or kStay.
  Status Draw(const std::vector<protocol::RegionReport>& regions, const CameraModel& camera,
              const Eigen::Matrix4f& local_from_remote, float near_m, float far_m, const Viewport& vp);

 private:
  RegionBoxes() = default;
  unsigned program_ = 0, vao_ = 0, vbo_ = 0;
};

// True while a region counts as occupied (enter or stay).
inline bool RegionOccupied(const protocol::RegionReport& r) {
  return r.state == protocol::RegionState::kEnter || r.state == protocol::RegionState::kStay;
}

}  // namespace holo::render
