// holoport-bench studio: frames per second of the synthetic studio rendering
// every pod of a workload, with ground truth (noise-free depth, masks,
// foreground mesh).
#include <chrono>
#include <ctime>
#include <cstdio>
#include <string>
#include <vector>

#include "bench.h"
#include "common/log.h"
#include "common/worker_pool.h"
#include "studio/studio.h"
#include "studio/workloads.h"

namespace {

int RunStudioBench(const holo::bench::BenchArgs& args) {
  auto workload = holo::GetWorkload(args.workload);
  if (!workload.ok()) {
    spdlog::error("studio: {}", workload.status().ToString());
    return 2;
  }
  auto studio = holo::SyntheticStudio::Create(workload->rig, workload->studio);
  if (!studio.ok()) {
    spdlog::error("studio: {}", studio.status().ToString());
    return 1;
  }
  const int frames = args.frames > 0 ? args.frames : 60;
  const int threads = holo::ResolveThreadCount(workload->studio.threads);
  holo::RgbdFrameSet set;
  holo::StudioGroundTruth gt;
  (*studio)->RenderFrame(0, &set, &gt);  // warm-up: buffers sized outside the timed loop
  std::vector<double> fps, ms, cpu_ms;
  for (int r = 0; r < args.repeats; ++r) {
    const auto t0 = std::chrono::steady_clock::now();
    const std::clock_t c0 = std::clock();
    for (int f = 0; f < frames; ++f) (*studio)->RenderFrame(f, &set, &gt);
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    // CPU time of all threads: a figure that other load on the machine barely changes.
    cpu_ms.push_back(1000.0 * static_cast<double>(std::clock() - c0) / CLOCKS_PER_SEC / frames);
    fps.push_back(frames / s);
    ms.push_back(1000.0 * s / frames);
    if (!args.json)
      spdlog::info("studio {} run {}: {} frames of {} pods in {:.3f} s: {:.1f} fps", workload->name, r + 1, frames,
                   set.frames.size(), s, fps.back());
  }
  const std::map<std::string, std::string> q = {{"threads", std::to_string(threads)}, {"ground_truth", "1"}, {"content", "truth"}};
  holo::bench::EmitFigure("studio", workload->name, "fps", holo::bench::Median(fps), "1/s", q);
  holo::bench::EmitFigure("studio", workload->name, "ms", holo::bench::Median(ms), "ms", q);
  holo::bench::EmitFigure("studio", workload->name, "cpu_ms", holo::bench::Median(cpu_ms), "ms", q);
  return 0;
}

}  // namespace

HOLO_REGISTER_BENCH_OPTIONS("studio", "synthetic studio: render all pods of a workload with ground truth",
                            holo::bench::NoOptions(RunStudioBench));
