// holoport-bench metrics: speed of the evaluation metrics every other
// benchmark relies on — 100k×100k Chamfer against the studio's ground-truth
// mesh (S8 workloads) and the closest-point index against brute force.
#include <algorithm>
#include <cstdio>
#include <limits>
#include <vector>

#include "bench.h"
#include "common/clock.h"
#include "common/log.h"
#include "common/metrics/mesh_distance.h"
#include "common/metrics/mesh_shapes.h"
#include "common/metrics/triangle_index.h"
#include "studio/studio.h"
#include "studio/workloads.h"

namespace holo::bench {
namespace {

int RunMetricsBench(const BenchArgs& args) {
  auto workload = GetWorkload(args.workload);
  if (!workload.ok()) {
    spdlog::error("holoport-bench: {}", workload.status().message());
    return 2;
  }
  SyntheticStudio studio(workload->rig, workload->studio);
  const Mesh truth = studio.ForegroundMesh(30);
  // A stand-in reconstruction: the truth one frame later (a few mm of motion).
  const Mesh recon = studio.ForegroundMesh(31);
  metrics::MeshDistanceOptions o;
  o.sampling.num_samples = args.frames > 0 ? args.frames : 100000;
  std::vector<double> ms;
  double chamfer = 0;
  for (int r = 0; r < args.repeats; ++r) {
    Stopwatch sw;
    auto d = metrics::ComputeMeshDistance(recon, truth, o);
    ms.push_back(sw.ElapsedMs());
    if (!d.ok()) {
      spdlog::error("holoport-bench: {}", d.status().message());
      return 1;
    }
    chamfer = d->chamfer_mm;
  }
  const std::string samples = std::to_string(o.sampling.num_samples);
  EmitFigure("metrics", args.workload, "ms", Median(ms), "ms",
             {{"stage", "chamfer"}, {"samples", samples}, {"triangles", std::to_string(truth.num_triangles())}});
  EmitFigure("metrics", args.workload, "chamfer_mm", chamfer, "mm", {{"stage", "chamfer"}, {"note", "frame 31 vs 30"}});

  // Index vs brute force on the same queries (one thread each).
  auto index = metrics::TriangleIndex::Build(truth);
  if (!index.ok()) return 1;
  std::vector<Eigen::Vector3f> queries;
  for (size_t i = 0; i < recon.positions.size(); i += 17) queries.push_back(recon.positions[i]);
  Stopwatch sw;
  auto fast = index->QueryBatch(queries, std::numeric_limits<float>::infinity(), 1);
  const double fast_ms = sw.ElapsedMs();
  sw.Restart();
  double sum = 0;
  for (const auto& q : queries) sum += index->QueryBruteForce(q).distance;
  const double brute_ms = sw.ElapsedMs();
  (void)sum;
  const std::string nq = std::to_string(queries.size());
  EmitFigure("metrics", args.workload, "us_per_query", 1000 * fast_ms / queries.size(), "us",
             {{"stage", "closest_point"}, {"queries", nq}});
  EmitFigure("metrics", args.workload, "us_per_query", 1000 * brute_ms / queries.size(), "us",
             {{"stage", "closest_point"}, {"queries", nq}, {"peer", "brute_force"}});
  EmitFigure("metrics", args.workload, "speedup_vs_brute_force", brute_ms / std::max(1e-6, fast_ms), "x",
             {{"stage", "closest_point"}});
  return 0;
}

}  // namespace

HOLO_REGISTER_BENCH_OPTIONS("metrics", "Chamfer 100k x 100k on the ground-truth mesh; closest-point index vs brute force",
                            NoOptions(RunMetricsBench));

}  // namespace holo::bench
