#include "studio/workloads.h"

namespace holo {
namespace {

struct WorkloadSpec {
  const char* name;
  const char* description;
  const char* rig;
  double scale;
  int figures, props;
  uint64_t seed;
  float voxel;
  int frames;
};

constexpr WorkloadSpec kSpecs[] = {
    {"S8-QVGA", "studio-8 rig at 320x240, one person and a bouncing ball, 8 mm voxels", "studio-8", 0.5, 1, 1, 1,
     0.008f, 300},
    {"S8-VGA", "studio-8 rig at 640x480, two people, a ball and a crate, 5 mm voxels", "studio-8", 1.0, 2, 2, 2,
     0.005f, 300},
    {"S4-QVGA", "studio-4 rig at 320x240, one person and a bouncing ball, 8 mm voxels", "studio-4", 0.5, 1, 1, 3,
     0.008f, 300},
};

}  // namespace

std::vector<std::string> WorkloadNames() {
  std::vector<std::string> names;
  for (const auto& s : kSpecs) names.push_back(s.name);
  return names;
}

StatusOr<Workload> GetWorkload(const std::string& name) {
  for (const auto& s : kSpecs) {
    if (name != s.name) continue;
    HOLO_ASSIGN_OR_RETURN(Rig rig, LoadRig(ShippedRigPath(s.rig)));
    Workload w;
    w.name = s.name;
    w.description = s.description;
    w.rig = s.scale == 1.0 ? rig : rig.Scaled(s.scale);
    w.studio.seed = s.seed;
    w.studio.num_figures = s.figures;
    w.studio.num_props = s.props;
    w.studio.fps = 30.0;
    w.voxel_size_m = s.voxel;
    w.num_frames = s.frames;
    w.stream_triangles = static_cast<size_t>(10000 * s.figures);
    return w;
  }
  std::string known;
  for (const auto& s : kSpecs) known += std::string(known.empty() ? "" : ", ") + s.name;
  return NotFound("unknown workload '" + name + "' (known: " + known + ")");
}

}  // namespace holo
