// The standard workloads every benchmark names (docs/workloads.md).
#pragma once

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
};

std::vector<std::string> WorkloadNames();
// NotFound naming the known workloads if `name` is unknown; errors from
// loading the shipped rig otherwise.
StatusOr<Workload> GetWorkload(const std::string& name);

}  // namespace holo
