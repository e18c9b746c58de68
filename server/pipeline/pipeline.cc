#include "server/pipeline/pipeline.h"

#include <time.h>

#include <algorithm>
#include <mutex>
#include <thread>

#include "common/bounded_queue.h"
#include "common/recent.h"

namespace holo {

Status PipelineOptions::Check() const {
  if (queue_capacity < 1 || queue_capacity > 64)
    return InvalidArgument("queue_capacity must be in [1, 64], got " + std::to_string(queue_capacity));
  if (pace_fps < 0 || pace_fps > 1000) return InvalidArgument("pace_fps must be in [0, 1000], got " + std::to_string(pace_fps));
  if (max_frames < -1) return InvalidArgument("max_frames must be >= -1, got " + std::to_string(max_frames));
  if (max_in_flight < 0 || max_in_flight > 256)
    return InvalidArgument("max_in_flight must be in [0, 256], got " + std::to_string(max_in_flight));
  if (keep_frame_timings < 0)
    return InvalidArgument("keep_frame_timings must be >= 0, got " + std::to_string(keep_frame_timings));
  return OkStatus();
}

Pipeline::Pipeline(PipelineStages stages, PipelineOptions options, Clock& clock)
    : stages_(std::move(stages)), options_(options), clock_(clock) {}

StatusOr<PipelineStats> Pipeline::Run() {
  HOLO_RETURN_IF_ERROR(options_.Check());
  if (!stages_.acquire) return InvalidArgument("pipeline needs an acquire stage");
  stop_ = false;
  return options_.serial ? RunSerial() : RunConcurrent();
}

double ProcessCpuTimeMs() {
  timespec ts{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return 1e3 * static_cast<double>(ts.tv_sec) + 1e-6 * static_cast<double>(ts.tv_nsec);
}

namespace {

// Runs `fn` on `work` and stores its wall time in `*ms` (and, if `cpu_ms` is
// set, the process CPU time meanwhile).
Status Timed(const std::function<Status(FrameWork&)>& fn, FrameWork& work, double* ms, double* cpu_ms = nullptr) {
  if (!fn) return OkStatus();
  const double cpu0 = cpu_ms ? ProcessCpuTimeMs() : 0;
  Stopwatch sw;
  Status s = fn(work);
  *ms = sw.ElapsedMs();
  if (cpu_ms) *cpu_ms = ProcessCpuTimeMs() - cpu0;
  return s;
}

Status RunFuseMesh(const std::function<Status(FrameWork&)>& fn, FrameWork& work, bool cpu = false) {
  if (!fn) return OkStatus();
  work.timings.fuse_ms = work.timings.mesh_ms = 0;
  work.timings.fuse_cpu_ms = work.timings.mesh_cpu_ms = 0;
  const double cpu0 = cpu ? ProcessCpuTimeMs() : 0;
  Stopwatch sw;
  Status s = fn(work);
  // The stage may split its own time into fuse and mesh; else it all counts as fuse.
  if (work.timings.fuse_ms == 0 && work.timings.mesh_ms == 0) work.timings.fuse_ms = sw.ElapsedMs();
  if (cpu && work.timings.fuse_cpu_ms == 0 && work.timings.mesh_cpu_ms == 0)
    work.timings.fuse_cpu_ms = ProcessCpuTimeMs() - cpu0;
  return s;
}

// Acquire with optional pacing. Returns OutOfRange at the end of the source.
// With drop_late_frames, `*seq` may advance past slots that have gone by.
Status Acquire(const PipelineStages& st, const PipelineOptions& opt, Clock& clock, int64_t* seq_io, int64_t start_us,
               FrameWork& work, int64_t* late, int64_t* dropped, bool cpu = false) {
  int64_t& seq = *seq_io;
  const int64_t period_us = opt.pace_fps > 0 ? static_cast<int64_t>(1e6 / opt.pace_fps) : 0;
  if (opt.pace_fps > 0) {
    const int64_t now = clock.NowUs();
    if (now > start_us + seq * period_us + period_us) {
      ++*late;
      if (opt.drop_late_frames) {
        const int64_t current = (now - start_us) / period_us;  // the slot whose frame the camera has now
        if (opt.max_frames >= 0) {
          *dropped += std::max<int64_t>(0, std::min(current, opt.max_frames) - seq);
          seq = std::min(current, opt.max_frames);
        } else {
          *dropped += current - seq;
          seq = current;
        }
        if (opt.max_frames >= 0 && seq >= opt.max_frames) return OutOfRange("no frames left after dropping late ones");
      }
    }
    clock.SleepUntilUs(start_us + seq * period_us);
  }
  work.sequence = seq;
  work.timings = StageTimings{};
  // A paced source is a camera: its frame was taken at its slot, even when
  // the pipeline picks it up late (within a period; later slots are skipped
  // or counted late). The capture time on the wire, which the voice is
  // synchronised with, is this one.
  work.timings.acquired_us = opt.pace_fps > 0 ? start_us + seq * period_us : clock.NowUs();
  return Timed(st.acquire, work, &work.timings.acquire_ms, cpu ? &work.timings.acquire_cpu_ms : nullptr);
}

}  // namespace

StatusOr<PipelineStats> Pipeline::RunSerial() {
  PipelineStats stats;
  FrameWork work;
  Stopwatch wall;
  const double cpu0 = ProcessCpuTimeMs();
  const int64_t start_us = clock_.NowUs();
  if (options_.on_start) options_.on_start(start_us);
  for (int64_t seq = 0; options_.max_frames < 0 || seq < options_.max_frames; ++seq) {
    if (stop_) break;
    Status s = Acquire(stages_, options_, clock_, &seq, start_us, work, &stats.late_frames, &stats.dropped_frames,
                       /*cpu=*/true);
    if (s.code() == StatusCode::kOutOfRange) break;
    HOLO_RETURN_IF_ERROR(s);
    HOLO_RETURN_IF_ERROR(Timed(stages_.segment, work, &work.timings.segment_ms, &work.timings.segment_cpu_ms));
    HOLO_RETURN_IF_ERROR(RunFuseMesh(stages_.fuse_mesh, work, /*cpu=*/true));
    HOLO_RETURN_IF_ERROR(Timed(stages_.texture, work, &work.timings.texture_ms, &work.timings.texture_cpu_ms));
    work.timings.ready_us = clock_.NowUs();
    HOLO_RETURN_IF_ERROR(Timed(stages_.encode, work, &work.timings.encode_ms, &work.timings.encode_cpu_ms));
    work.timings.encoded_us = clock_.NowUs();
    if (stages_.sink) HOLO_RETURN_IF_ERROR(stages_.sink(work));
    AppendRecent(&stats.per_frame, work.timings, static_cast<size_t>(options_.keep_frame_timings));
    ++stats.frames;
  }
  stats.cpu_ms = ProcessCpuTimeMs() - cpu0;
  stats.wall_seconds = wall.ElapsedMs() * 1e-3;
  stats.fps = stats.wall_seconds > 0 ? static_cast<double>(stats.frames) / stats.wall_seconds : 0;
  return stats;
}

StatusOr<PipelineStats> Pipeline::RunConcurrent() {
  using Queue = BoundedQueue<FrameWork*>;
  const size_t cap = static_cast<size_t>(options_.queue_capacity);
  // Items: one inside each of the 6 threads plus a full queue on each of the 5 hops.
  const size_t pool_size = options_.max_in_flight > 0 ? static_cast<size_t>(options_.max_in_flight) : 6 + 5 * cap;
  std::vector<std::unique_ptr<FrameWork>> pool;
  Queue free_items(pool_size), to_segment(cap), to_fuse(cap), to_texture(cap), to_encode(cap), to_sink(cap);
  for (size_t i = 0; i < pool_size; ++i) {
    pool.push_back(std::make_unique<FrameWork>());
    free_items.Push(pool.back().get());
  }
  std::mutex mu;
  Status first_error;
  PipelineStats stats;
  auto fail = [&](const Status& s) {
    {
      std::lock_guard lock(mu);
      if (first_error.ok()) first_error = s;
    }
    for (Queue* q : {&free_items, &to_segment, &to_fuse, &to_texture, &to_encode, &to_sink}) q->Close();
  };

  Stopwatch wall;
  const double cpu0 = ProcessCpuTimeMs();
  const int64_t start_us = clock_.NowUs();
  if (options_.on_start) options_.on_start(start_us);
  std::thread acquire_thread([&] {
    int64_t late = 0, dropped = 0;
    for (int64_t seq = 0; options_.max_frames < 0 || seq < options_.max_frames; ++seq) {
      if (stop_) break;
      auto item = free_items.Pop();
      if (!item) break;
      Status s = Acquire(stages_, options_, clock_, &seq, start_us, **item, &late, &dropped);
      if (s.code() == StatusCode::kOutOfRange) break;
      if (!s.ok()) {
        // A bad input frame ends the stream: frames already acquired still go
        // through and reach the sink (as in serial mode), then Run fails.
        std::lock_guard lock(mu);
        if (first_error.ok()) first_error = s;
        break;
      }
      if (!to_segment.Push(*item)) break;
    }
    {
      std::lock_guard lock(mu);
      stats.late_frames = late;
      stats.dropped_frames = dropped;
    }
    to_segment.Close();
  });
  // A middle stage: pop, process, push on; closes its output when its input ends.
  auto middle = [&](Queue& in, Queue& out, auto process) {
    return std::thread([&in, &out, process, &fail] {
      while (auto item = in.Pop()) {
        Status s = process(**item);
        if (!s.ok()) {
          fail(s);
          break;
        }
        if (!out.Push(*item)) break;
      }
      out.Close();
    });
  };
  std::thread segment_thread = middle(to_segment, to_fuse, [&](FrameWork& w) {
    return Timed(stages_.segment, w, &w.timings.segment_ms);
  });
  std::thread fuse_thread = middle(to_fuse, to_texture, [&](FrameWork& w) { return RunFuseMesh(stages_.fuse_mesh, w); });
  std::thread texture_thread = middle(to_texture, to_encode, [&](FrameWork& w) {
    Status s = Timed(stages_.texture, w, &w.timings.texture_ms);
    w.timings.ready_us = clock_.NowUs();
    return s;
  });
  std::thread encode_thread = middle(to_encode, to_sink, [&](FrameWork& w) {
    Status s = Timed(stages_.encode, w, &w.timings.encode_ms);
    w.timings.encoded_us = clock_.NowUs();
    return s;
  });
  std::thread sink_thread([&] {
    while (auto item = to_sink.Pop()) {
      if (stages_.sink) {
        Status s = stages_.sink(**item);
        if (!s.ok()) {
          fail(s);
          break;
        }
      }
      AppendRecent(&stats.per_frame, (*item)->timings, static_cast<size_t>(options_.keep_frame_timings));
      ++stats.frames;
      free_items.Push(*item);
    }
  });
  for (std::thread* t : {&acquire_thread, &segment_thread, &fuse_thread, &texture_thread, &encode_thread, &sink_thread})
    t->join();
  if (!first_error.ok()) return first_error;
  stats.cpu_ms = ProcessCpuTimeMs() - cpu0;
  stats.wall_seconds = wall.ElapsedMs() * 1e-3;
  stats.fps = stats.wall_seconds > 0 ? static_cast<double>(stats.frames) / stats.wall_seconds : 0;
  return stats;
}

namespace {
double MedianOf(std::vector<double> v) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  const size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}
}  // namespace

StageTimings MedianTimings(const PipelineStats& stats) {
  StageTimings m;
  auto med = [&](double StageTimings::*field) {
    std::vector<double> v;
    for (const auto& t : stats.per_frame) v.push_back(t.*field);
    return MedianOf(v);
  };
  m.acquire_ms = med(&StageTimings::acquire_ms);
  m.segment_ms = med(&StageTimings::segment_ms);
  m.fuse_ms = med(&StageTimings::fuse_ms);
  m.mesh_ms = med(&StageTimings::mesh_ms);
  m.simplify_ms = med(&StageTimings::simplify_ms);
  m.texture_ms = med(&StageTimings::texture_ms);
  m.encode_ms = med(&StageTimings::encode_ms);
  m.regions_ms = med(&StageTimings::regions_ms);
  m.regions_cpu_ms = med(&StageTimings::regions_cpu_ms);
  m.acquire_cpu_ms = med(&StageTimings::acquire_cpu_ms);
  m.segment_cpu_ms = med(&StageTimings::segment_cpu_ms);
  m.fuse_cpu_ms = med(&StageTimings::fuse_cpu_ms);
  m.mesh_cpu_ms = med(&StageTimings::mesh_cpu_ms);
  m.simplify_cpu_ms = med(&StageTimings::simplify_cpu_ms);
  m.texture_cpu_ms = med(&StageTimings::texture_cpu_ms);
  m.encode_cpu_ms = med(&StageTimings::encode_cpu_ms);
  return m;
}

double MedianLatencyMs(const PipelineStats& stats) {
  std::vector<double> v;
  for (const auto& t : stats.per_frame) v.push_back(t.latency_ms());
  return MedianOf(v);
}

}  // namespace holo
