// The capture pipeline: stages that run concurrently on bounded queues
// (acquire ‖ segment ‖ fuse+mesh ‖ texture ‖ encode ‖ sink), each timed.
//
// Work items circulate: a fixed pool of FrameWork objects is created up
// front; acquire takes a free one, every stage fills its part in place
// (reusing the buffers of earlier frames), the sink reads it and the item
// returns to the pool. In steady state nothing is allocated per frame.
//
// The pipeline knows nothing of what the stages do: they are functions, so
// the same scheduler runs the real stages, test doubles, and (in serial mode)
// the reference order for tests.
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "common/clock.h"
#include "common/mesh.h"
#include "common/rgbd.h"
#include "common/sdf_grid.h"
#include "common/status.h"

namespace holo {

// Per-frame timings, milliseconds of wall time inside each stage.
struct StageTimings {
  double acquire_ms = 0;
  double segment_ms = 0;
  double fuse_ms = 0;
  double mesh_ms = 0;
  double simplify_ms = 0;  // part of the fuse+mesh stage: the stream mesh (set by the stage itself)
  double texture_ms = 0;
  double encode_ms = 0;
  // Active regions (server/regions/): occupancy of every configured region
  // from the frame's mesh, wall and CPU time of the thread that ran it (set
  // by whoever tracks regions; 0 without regions).
  double regions_ms = 0;
  double regions_cpu_ms = 0;
  // Serial mode only (0 otherwise): CPU time of the whole process (all
  // threads, worker pools included) while each stage ran, ms. With one stage
  // at a time this is that stage's CPU cost, which other load on the machine
  // barely changes. `fuse_mesh` may split its own into fuse and mesh.
  double acquire_cpu_ms = 0;
  double segment_cpu_ms = 0;
  double fuse_cpu_ms = 0;
  double mesh_cpu_ms = 0;
  double simplify_cpu_ms = 0;
  double texture_cpu_ms = 0;
  double encode_cpu_ms = 0;
  // Clock time of the frame's capture (paced: its camera slot; else when acquire
  // started), when the texture stage finished and when
  // the encode stage finished (µs on the pipeline's clock; encoded_us =
  // ready_us without an encode stage): latency = ready - acquired.
  int64_t acquired_us = 0;
  int64_t ready_us = 0;
  int64_t encoded_us = 0;
  double latency_ms() const { return static_cast<double>(ready_us - acquired_us) * 1e-3; }
  double encoded_latency_ms() const { return static_cast<double>(encoded_us - acquired_us) * 1e-3; }
};

// One frame's work item: owned by the pipeline, lent to each stage in turn.
struct FrameWork {
  int64_t sequence = 0;  // 0, 1, 2, ... in acquisition order
  RgbdFrameSet frames;   // pods' colour, depth, and (after segment) masks
  Mesh mesh;             // after fuse+mesh: geometry; after texture: colours
  Mesh full_mesh;        // optional: the full-resolution mesh when `mesh` is a reduced stream mesh
  SdfGrid stream_field;  // optional: the distance grid `mesh` was extracted from (G3 geometry)
  // What the encode stage made for the sink (owned by the stage that set it;
  // kept with the item, so its buffers are reused frame after frame).
  std::shared_ptr<void> encoded;
  StageTimings timings;
  // Stage-private scratch a stage may keep with the item (e.g. the fused
  // mesh before clean-up); nothing outside that stage reads it.
  std::shared_ptr<void> scratch;
};

// Stage functions. Each returns an error to stop the pipeline (the error is
// returned by Run). An acquire error ends the stream after the frames already
// acquired have reached the sink; an error in a later stage stops at once. A stage may be empty (skipped). `work` is valid only
// during the call. `fuse_mesh` sets timings.fuse_ms and timings.mesh_ms
// itself (the pipeline times the call as a whole into fuse_ms otherwise).
struct PipelineStages {
  // Fills work.frames; returns OutOfRange at the end of the source.
  std::function<Status(FrameWork& work)> acquire;
  std::function<Status(FrameWork& work)> segment;
  std::function<Status(FrameWork& work)> fuse_mesh;
  std::function<Status(FrameWork& work)> texture;
  // Compresses the frame for streaming (the capture site: G1 + C1 into the
  // work item's scratch), on its own thread.
  std::function<Status(FrameWork& work)> encode;
  // Receives finished frames in order. Runs on its own thread.
  std::function<Status(const FrameWork& work)> sink;
};

struct PipelineOptions {
  // Capacity of each queue between stages (frames in flight per hop).
  int queue_capacity = 2;
  // Run all stages one after another on the calling thread (reference order
  // for tests; also the single-core mode).
  bool serial = false;
  // Stop after this many frames (-1: until the source ends).
  int64_t max_frames = -1;
  // If > 0, acquire is paced to this rate (a live camera). A slow stage
  // backs up to acquire, and the pacing reports `late_frames`.
  double pace_fps = 0;
  // Paced mode: when acquisition falls a whole period or more behind its
  // slot, skip to the current slot as a live camera would (the frames of
  // the skipped slots are never taken; sequence numbers jump and
  // `dropped_frames` counts them), so latency stays bounded when the site
  // cannot keep up. Off: every frame is taken, however late.
  bool drop_late_frames = false;
  // Frames in the pipeline at once (acquired, not yet through the sink);
  // 0 = as many as the queues hold. Fewer in flight = lower latency when a
  // stage is the bottleneck (each frame waits behind fewer others).
  int max_in_flight = 0;
  // Per-frame timings kept in PipelineStats::per_frame: 0 = every frame;
  // N > 0 = only the newest N to 2N frames (older ones are dropped N at a
  // time). A site that runs for days must not grow by a StageTimings (136
  // bytes) per frame: 15 MB an hour at 30 fps.
  int64_t keep_frame_timings = 0;
  // Called once when Run starts, with the pacing origin on the pipeline's
  // clock: paced, frame `sequence` k is the camera frame of time start_us +
  // k / pace_fps (what the site's voice lines up with).
  std::function<void(int64_t start_us)> on_start;
  Status Check() const;
};

struct PipelineStats {
  int64_t frames = 0;
  double wall_seconds = 0;
  double fps = 0;
  int64_t late_frames = 0;  // paced mode: frames acquired later than their slot
  int64_t dropped_frames = 0;  // paced mode with drop_late_frames: camera slots skipped
  // CPU time of the whole process (all threads) during Run, ms: divided by
  // `frames`, the CPU cost of a frame with every stage and all overheads.
  double cpu_ms = 0;
  std::vector<StageTimings> per_frame;  // in order (the newest ones only with keep_frame_timings)
};

// Runs the stages until the source ends, `max_frames` are done, a stage
// fails, or Stop() is called. Returns the stats, or the first stage error.
class Pipeline {
 public:
  Pipeline(PipelineStages stages, PipelineOptions options, Clock& clock = RealClock::Instance());
  Pipeline(const Pipeline&) = delete;
  Pipeline& operator=(const Pipeline&) = delete;

  StatusOr<PipelineStats> Run();
  // Asks a running pipeline to stop after the frames in flight (thread-safe).
  void Stop() { stop_ = true; }

 private:
  StatusOr<PipelineStats> RunSerial();
  StatusOr<PipelineStats> RunConcurrent();

  PipelineStages stages_;
  PipelineOptions options_;
  Clock& clock_;
  std::atomic<bool> stop_{false};
};

// CPU time of the whole process so far (all threads), ms.
double ProcessCpuTimeMs();

// Median of each stage's time over `stats.per_frame` (ms), CPU fields included.
StageTimings MedianTimings(const PipelineStats& stats);
double MedianLatencyMs(const PipelineStats& stats);

}  // namespace holo
