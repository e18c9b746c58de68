// The standard workloads every benchmark names (docs/workloads.md).
#pragma once

#include <cstddef>
#include <string>
#include <vector>

#include "common/rig.h"
#include "common/status.h"
#include "studio/studio.h"

namespace holo {

struct Workload {
  std::string name;         // "S8-QVGA"
  std::string description;  // one line
  Rig rig;                  // pods at the workload's resolution
  StudioOptions studio;     // content and seed
  float voxel_size_m = 0;   // fusion voxel size the workload is judged at
  int num_frames = 0;       // standard length (frames at studio.fps)
  // The stream mesh's triangle budget a site publishes the scene with
  // (StreamMeshOptions::max_triangles): 10 k per person. On S8-QVGA 10 k
  // keep the mesh within 1.3 mm of the full one at the viewer's PSNR of
  // 20 k, at the rendering viewer's per-mesh cost of half (docs/live.md);
  // S8-VGA's two people lose 0.2–0.3 dB at 10 k, so they get 20 k.
  size_t stream_triangles = 0;
};

std::vector<std::string> WorkloadNames();
// NotFound naming the known workloads if `name` is unknown; errors from
// loading the shipped rig otherwise.
StatusOr<Workload> GetWorkload(const std::string& name);

}  // namespace holo
