// holoport-bench regions: active regions end to end (docs/regions.md).
//
// A site (holoport-server, its own process) fuses the studio's S8-QVGA pods
// live at 30 fps (pre-rendered loop, as `holoport-bench live`) with one
// active region, and a viewer (SiteClient, this process) subscribes to its
// Regions over loopback. The region is a 30 cm box the person's body enters
// and leaves: picked before the run from the studio's known animation (the
// box, among a grid of candidates above the props' reach, with the most
// clean entries in the loop). Ground truth (TrueEvents): the region's state
// from the studio's true mesh with the same volume thresholds, no debounce,
// no noise; an entry's time is the body's first contact with the box.
//
// Figures (content fused unless said):
//   event_latency_ms p50/p99 (event enter, from contact|threshold; event
//     leave, from threshold): capture time of the frame in which the true
//     body first touches the box (contact), or in which its true volume
//     crosses the enter (exit) threshold (threshold) → the viewer receiving
//     the Regions message that reports the event (a forearm that hovers at
//     the box's edge fills it slowly: that wait is the body's, not the
//     pipeline's; without --json the slow events are listed with both
//     frames). An exit is timed from its volume crossing only: a fingertip
//     may stay in after the body has left;
//   detection_frames: frames from the contact (exit: the crossing) to the
//     frame whose report fired;
//   missed_events, false_events: true entries/exits without an event within
//     the debounce window, and events with no true entry/exit (an event that
//     answers a true change too close to the run's end to be counted is
//     neither);
//   report_latency_ms p50/p99: every report's own delay (capture of its
//     frame → viewer), i.e. the site's pipeline and the network in the same
//     run, and site_fps, the frames the site fused per second: an event's
//     latency is the report latency plus the detection frames;
//   regions_cpu_ms: the site's occupancy stage, CPU-ms per frame (median);
//   still_false_events (content truth): a still body with the studio's depth
//     noise (σ 3 mm jitter + 1 % flying points, new every frame) for 900
//     frames through the same tracker, its true volume between the
//     thresholds (no event allowed) or just over the enter threshold (one
//     entry allowed): events beyond those (must be 0);
//   occupancy_cpu_us (content truth): the tracker on the true mesh;
//   detection_frames, missed_events, false_events (content truth, fps 30):
//     the tracker alone on the true meshes of every camera frame — what the
//     thresholds and debounce cost, without the site's pipeline.
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <memory>
#include <mutex>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "bench.h"
#include "bench_process.h"
#include "common/clock.h"
#include "common/log.h"
#include "common/quantile.h"
#include "net/site_client.h"
#include "server/capture/prerendered.h"
#include "server/regions/regions.h"
#include "studio/studio.h"
#include "studio/workloads.h"

namespace holo::bench {
namespace {

constexpr char kRegionsPublisherToken[] = "regions-bench-publisher";
constexpr char kRegionsViewerToken[] = "regions-bench-viewer";

struct RegionsBenchOptions {
  double seconds = 40;
  int prerender = 150;
  std::string site_binary;
  std::string keep_dir;
};

struct Received {
  int64_t frame = 0;
  protocol::RegionState state = protocol::RegionState::kEmpty;
  int64_t capture_us = 0;
  int64_t received_us = 0;
};

regions::RegionSpec Box(const Eigen::Vector3f& centre, float edge, const regions::RegionsConfig& defaults) {
  regions::RegionSpec r;
  r.name = "touch";
  r.shape = protocol::RegionShape::kBox;
  r.min = centre - Eigen::Vector3f::Constant(edge / 2);
  r.max = centre + Eigen::Vector3f::Constant(edge / 2);
  r.enter_litres = defaults.enter_litres;
  r.exit_litres = defaults.exit_litres;
  return r;
}

bool TrulyOccupied(const regions::RegionSpec& r, const Mesh& m) {
  for (const auto& p : m.positions)
    if (r.Contains(p)) return true;
  return false;
}

// The true events over sequences [first, last] of the site's ping-pong loop
// of `truth`: the region's state from the true mesh's occupied volume with
// the config's thresholds (hysteresis, no frame debounce — the definition
// the site applies, without noise). An entry's `anchor` is the body's first
// frame of contact (going back from the volume crossing while a true vertex
// is inside), an exit's is the volume crossing itself (a fingertip may stay
// in after the body has left).
struct TrueEvent {
  int64_t anchor = 0;
  int64_t change = 0;
  bool enter = false;
};
std::vector<TrueEvent> TrueEvents(const std::vector<Mesh>& truth, const regions::RegionsConfig& c, int64_t first,
                                  int64_t last) {
  const regions::RegionSpec& r = c.regions[0];
  const int64_t n = static_cast<int64_t>(truth.size());
  std::vector<float> vol(truth.size());
  std::vector<bool> contact(truth.size());
  std::vector<uint64_t> scratch;
  for (size_t k = 0; k < truth.size(); ++k) {
    vol[k] = OccupiedLitres(r, truth[k].positions, c.cell_m, c.min_points_per_cell, &scratch);
    contact[k] = TrulyOccupied(r, truth[k]);
  }
  auto at = [&](int64_t k) { return static_cast<size_t>(LoopContent(k, n)); };
  std::vector<TrueEvent> out;
  bool occupied = vol[at(first)] >= r.enter_litres;
  for (int64_t k = first + 1; k <= last; ++k) {
    const float v = vol[at(k)];
    if (!occupied && v >= r.enter_litres) {
      occupied = true;
      int64_t a = k;
      while (a - 1 > first && contact[at(a - 1)]) --a;
      out.push_back({a, k, true});
    } else if (occupied && v < r.exit_litres) {
      occupied = false;
      out.push_back({k, k, false});
    }
  }
  return out;
}

struct Matched {
  std::map<std::string, std::vector<double>> frames;  // event frame − anchor, per kind
  std::vector<std::pair<int64_t, int64_t>> pairs;      // (anchor, event frame) of every match, for latencies
  std::vector<bool> kinds_enter;
  std::vector<int64_t> changes;  // the true change of every match
  std::vector<bool> used;  // per reported event: answers a true change
  int counted = 0, missed = 0, false_events = 0;
};

// Matches reported events (frame, enter?) to the true ones: the first event
// of the same kind from the anchor up to `window` frames after the next true
// change. True events too close to `last` to be reported are not counted,
// and neither is an event that answers one of them (it is not false).
Matched MatchEvents(const std::vector<TrueEvent>& truth, const std::vector<std::pair<int64_t, bool>>& events,
                    int64_t last, int64_t window) {
  Matched m;
  std::vector<bool> used(events.size(), false);
  for (size_t i = 0; i < truth.size(); ++i) {
    const TrueEvent& t = truth[i];
    const int64_t until = i + 1 < truth.size() ? truth[i + 1].change + window : t.change + 4 * window;
    const bool counted = until <= last;
    m.counted += counted;
    bool found = false;
    for (size_t e = 0; e < events.size() && !found; ++e) {
      if (used[e] || events[e].second != t.enter || events[e].first < t.anchor || events[e].first > until) continue;
      used[e] = found = true;
      if (!counted) break;
      m.frames[t.enter ? "enter" : "leave"].push_back(static_cast<double>(events[e].first - t.anchor));
      m.pairs.push_back({t.anchor, events[e].first});
      m.kinds_enter.push_back(t.enter);
      m.changes.push_back(t.change);
    }
    if (counted && !found) ++m.missed;
  }
  for (size_t e = 0; e < events.size(); ++e)
    if (!used[e] && events[e].first <= last - window) ++m.false_events;
  m.used = std::move(used);
  return m;
}

// Picks the candidate box with the most clean entries (occupied and empty
// stretches of ≥ 6 frames, and deep enough for the default thresholds) over
// the ping-pong loop of `meshes`.
regions::RegionSpec PickRegion(const std::vector<Mesh>& meshes, const regions::RegionsConfig& defaults,
                               int* entries_out) {
  regions::RegionSpec best;
  int best_score = -1;
  float best_peak = 0;
  std::vector<uint64_t> scratch;
  const int64_t n = static_cast<int64_t>(meshes.size());
  for (float z = 1.0f; z <= 1.91f; z += 0.15f)
    for (float x = -0.9f; x <= 0.91f; x += 0.15f)
      for (float y = -0.9f; y <= 0.91f; y += 0.15f) {
        const regions::RegionSpec r = Box({x, y, z}, 0.3f, defaults);
        std::vector<int> occ(static_cast<size_t>(2 * n - 2));
        std::vector<float> vol(occ.size());
        for (size_t k = 0; k < occ.size(); ++k) {
          const Mesh& m = meshes[static_cast<size_t>(LoopContent(static_cast<int64_t>(k), n))];
          occ[k] = TrulyOccupied(r, m);
          vol[k] = occ[k] ? OccupiedLitres(r, m.positions, defaults.cell_m, 1, &scratch) : 0.0f;
        }
        // Stretches over one lap of the loop (it repeats).
        int score = 0;
        float peak = 0;
        size_t k = 0;
        while (k < occ.size() && occ[k]) ++k;  // start outside
        while (k < occ.size()) {
          size_t e = k;
          while (e < occ.size() && !occ[e]) ++e;
          const size_t empty_len = e - k;
          size_t x2 = e;
          float p = 0;
          while (x2 < occ.size() && occ[x2]) p = std::max(p, vol[x2++]);
          if (x2 == occ.size()) break;  // the last stretch runs past the lap
          if (empty_len >= 6 && x2 - e >= 6 && p >= 2 * defaults.enter_litres) {
            ++score;
            peak = std::max(peak, p);
          }
          k = x2;
        }
        if (score > best_score || (score == best_score && peak > best_peak)) {
          best_score = score;
          best_peak = peak;
          best = r;
        }
      }
  *entries_out = best_score;
  return best;
}

int RunRegionsBench(const BenchArgs& args, const RegionsBenchOptions& o) {
  auto workload = GetWorkload(args.workload);
  if (!workload.ok()) {
    spdlog::error("regions: {}", workload.status().ToString());
    return 2;
  }
  const std::string wl = workload->name;
  const std::string site_binary = o.site_binary.empty() ? SelfDir() + "/holoport-server" : o.site_binary;
  if (access(site_binary.c_str(), X_OK) != 0) {
    spdlog::error("regions: site program {} not found (build holoport-server or pass --site)", site_binary);
    return 2;
  }
  auto progress = [&](const std::string& s) {
    if (!args.json) spdlog::info("regions: {}", s);
  };
  std::string dir = o.keep_dir;
  if (dir.empty()) {
    char tmpl[] = "/tmp/holoport-regions-XXXXXX";
    if (!mkdtemp(tmpl)) return 1;
    dir = tmpl;
  } else if (std::system(("mkdir -p '" + dir + "'").c_str()) != 0) {
    return 1;
  }

  // Ground truth: the studio's true meshes of the pre-rendered frames.
  auto studio = SyntheticStudio::Create(workload->rig, workload->studio);
  if (!studio.ok()) {
    spdlog::error("regions: {}", studio.status().ToString());
    return 1;
  }
  std::vector<Mesh> truth;
  for (int k = 0; k < o.prerender; ++k) truth.push_back((*studio)->ForegroundMesh(k));
  regions::RegionsConfig defaults;
  int lap_entries = 0;
  regions::RegionSpec region = PickRegion(truth, defaults, &lap_entries);
  if (lap_entries <= 0) {
    spdlog::error("regions: no candidate box is entered cleanly in {} frames of {}", o.prerender, wl);
    return 1;
  }
  char where[160];
  std::snprintf(where, sizeof where, "[%.2f, %.2f, %.2f]..[%.2f, %.2f, %.2f]", region.min.x(), region.min.y(),
                region.min.z(), region.max.x(), region.max.y(), region.max.z());
  progress(std::string("region 'touch' = box ") + where + ", " + std::to_string(lap_entries) +
           " clean entries per lap of the loop");
  {
    std::ofstream f(dir + "/regions.yaml");
    f << "# holoport-bench regions: the box picked from the studio's animation\n"
      << "regions:\n  - name: touch\n    box: {min: [" << region.min.x() << ", " << region.min.y() << ", "
      << region.min.z() << "], max: [" << region.max.x() << ", " << region.max.y() << ", " << region.max.z()
      << "]}\n";
  }
  auto config = regions::LoadRegionsConfig(dir + "/regions.yaml");
  if (!config.ok()) {
    spdlog::error("regions: {}", config.status().ToString());
    return 1;
  }
  const std::map<std::string, std::string> q_fused = {{"content", "fused"}, {"region", where}};
  const std::map<std::string, std::string> q_truth = {{"content", "truth"}, {"region", where}};

  // 1. In-process: the tracker on the true meshes (CPU), and the still scene with noise.
  {
    regions::RegionTracker tracker(*config);
    std::vector<double> cpu_us;
    for (int rep = 0; rep < 3; ++rep)
      for (size_t k = 0; k < truth.size(); ++k) {
        const double c0 = ThreadCpuTimeMs();
        tracker.Update(static_cast<int64_t>(k), truth[k].positions);
        cpu_us.push_back((ThreadCpuTimeMs() - c0) * 1e3);
      }
    EmitFigure("regions", wl, "occupancy_cpu_us", Median(cpu_us), "us",
               [&] { auto q = q_truth; q["vertices"] = std::to_string(truth[0].num_vertices()); return q; }());
    // Still scenes with noise: the body held still where the true occupied
    // volume is (a) between the exit and enter thresholds (nothing may fire)
    // and (b) just over the enter threshold (one entry, then nothing). Noise:
    // σ 3 mm jitter on every point (the studio's depth noise at 1 m) and 1 %
    // flying points moved up to 5 cm, new every frame.
    std::vector<uint64_t> scratch;
    const regions::RegionSpec& reg = config->regions[0];
    auto still_frame = [&](float target) {
      size_t best_k = 0;
      float best = 1e9f;
      for (size_t k = 0; k < truth.size(); ++k) {
        const float v = OccupiedLitres(reg, truth[k].positions, config->cell_m, config->min_points_per_cell, &scratch);
        if (v > 0 && std::abs(v - target) < best) {
          best = std::abs(v - target);
          best_k = k;
        }
      }
      return best_k;
    };
    struct Still {
      const char* name;
      float target;
      int allowed;  // events a correct tracker fires
    };
    for (const Still& st : {Still{"between_thresholds", 0.5f * (reg.enter_litres + reg.exit_litres), 0},
                            Still{"just_over_enter", reg.enter_litres * 1.15f, 1}}) {
      const size_t still = still_frame(st.target);
      regions::RegionTracker quiet(*config);
      std::mt19937 rng(11);
      std::normal_distribution<float> jitter(0.0f, 0.003f);
      std::uniform_real_distribution<float> u(-1.0f, 1.0f);
      std::vector<Eigen::Vector3f> pts;
      const int64_t frames = 900;
      for (int64_t f = 0; f < frames; ++f) {
        pts = truth[still].positions;
        for (auto& p : pts) p += Eigen::Vector3f(jitter(rng), jitter(rng), jitter(rng));
        for (size_t i = 0; i < pts.size() / 100; ++i)
          pts[rng() % pts.size()] += 0.05f * Eigen::Vector3f(u(rng), u(rng), u(rng));
        quiet.Update(f, pts);
      }
      char sv[32];
      std::snprintf(sv, sizeof sv, "%.2f",
                    OccupiedLitres(reg, truth[still].positions, config->cell_m, config->min_points_per_cell, &scratch));
      auto q = q_truth;
      q["still"] = st.name;
      q["frames"] = std::to_string(frames);
      q["noise"] = "sigma 3 mm + 1% flying 5 cm";
      q["still_litres"] = sv;
      EmitFigure("regions", wl, "still_false_events",
                 static_cast<double>(std::abs(quiet.events() - st.allowed)), "count", q);
    }
  }

  // 1b. The tracker alone on the true meshes at 30 fps (every camera frame,
  // no pipeline, no noise): what the debounce costs in frames, and which true
  // visits it misses.
  const int64_t window = config->enter_frames + config->exit_frames + 15;
  {
    regions::RegionTracker t(*config);
    const int64_t n = static_cast<int64_t>(truth.size());
    const int64_t seqs = 4 * (n - 1);  // two laps of the loop
    std::vector<std::pair<int64_t, bool>> events;
    for (int64_t k = 0; k < seqs; ++k)
      for (const auto& g : t.Update(k, truth[static_cast<size_t>(LoopContent(k, n))].positions).regions)
        if (g.state == protocol::RegionState::kEnter || g.state == protocol::RegionState::kLeave)
          events.push_back({k, g.state == protocol::RegionState::kEnter});
    const Matched m = MatchEvents(TrueEvents(truth, *config, 0, seqs - 1), events, seqs - 1, window);
    for (const auto& [kind, v] : m.frames) {
      auto q = q_truth;
      q["event"] = kind;
      q["n"] = std::to_string(v.size());
      q["fps"] = "30";
      EmitFigure("regions", wl, "detection_frames", Median(v), "frames", q);
    }
    auto q = q_truth;
    q["fps"] = "30";
    EmitFigure("regions", wl, "true_events", m.counted, "count", q);
    EmitFigure("regions", wl, "missed_events", m.missed, "count", q);
    EmitFigure("regions", wl, "false_events", m.false_events, "count", q);
  }

  // 2. The live run: the site fuses, the viewer receives the events.
  const uint16_t port = FreeTcpPort();
  const std::string stats_path = dir + "/site_stats.jsonl";
  std::vector<std::string> argv = {site_binary, "--source", "synthetic", "--workload", wl, "--listen",
                                   "127.0.0.1:" + std::to_string(port), "--publisher-token", kRegionsPublisherToken,
                                   "--viewer-token", kRegionsViewerToken, "--stats", stats_path, "--pace", "30",
                                   "--prerender", std::to_string(o.prerender), "-n", "-1", "--regions",
                                   dir + "/regions.yaml"};
  progress("starting the site (fused " + wl + ", pre-rendering " + std::to_string(o.prerender) + " frames) on port " +
           std::to_string(port));
  const pid_t site = SpawnLogged(argv, dir + "/site.log", /*tied=*/true);
  if (site < 0) return 1;
  struct Guard {
    pid_t pid;
    ~Guard() { StopProcess(pid, SIGTERM, 5); }
  } guard{site};

  std::mutex mu;
  std::vector<Received> got;          // events of the region
  std::map<int64_t, int64_t> capture;  // frame → capture time (every report)
  std::map<int64_t, int64_t> received_at;  // frame → when the viewer received its report
  net::ClientOptions co;
  co.port = port;
  co.token = kRegionsViewerToken;
  co.name = "regions-bench";
  co.subscribe = net::kSubscribeGeometry | net::kSubscribeRegions;  // geometry: a viewer's usual load
  co.decode = false;
  co.connect_timeout_s = 120;
  co.backoff_initial_s = 0.2;
  co.backoff_max_s = 1.0;
  net::ClientCallbacks cb;
  cb.on_regions = [&](const net::ReceivedRegions& r) {
    std::lock_guard<std::mutex> l(mu);
    capture[r.regions.frame_index] = r.capture_time_us;
    received_at[r.regions.frame_index] = r.received_us;
    for (const auto& g : r.regions.regions)
      if (g.state == protocol::RegionState::kEnter || g.state == protocol::RegionState::kLeave)
        got.push_back({r.regions.frame_index, g.state, r.capture_time_us, r.received_us});
  };
  auto client = net::SiteClient::Start(co, cb);
  if (!client.ok()) {
    spdlog::error("regions: {}", client.status().ToString());
    return 1;
  }
  // The site pre-renders first (tens of seconds); wait for its reports.
  const auto t0 = std::chrono::steady_clock::now();
  for (;;) {
    {
      std::lock_guard<std::mutex> l(mu);
      if (!capture.empty()) break;
    }
    int st = 0;
    if (waitpid(site, &st, WNOHANG) == site) {
      guard.pid = -1;
      spdlog::error("regions: the site exited early (see {}/site.log)", dir);
      return 1;
    }
    if (std::chrono::steady_clock::now() - t0 > std::chrono::seconds(300)) {
      spdlog::error("regions: no Regions report within 300 s (see {}/site.log)", dir);
      return 1;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  progress("receiving reports for " + std::to_string(static_cast<int>(o.seconds)) + " s");
  std::this_thread::sleep_for(std::chrono::duration<double>(o.seconds));
  (*client)->Stop();
  const net::ClientStats cs = (*client)->stats();
  StopProcess(site, SIGTERM, 10);
  guard.pid = -1;

  // True entries and exits over the frames the run covered.
  std::lock_guard<std::mutex> l(mu);
  const int64_t first = capture.begin()->first, last = capture.rbegin()->first;
  auto capture_of = [&](int64_t k) {  // paced: slots 1/30 s apart
    auto it = capture.lower_bound(k);
    if (it == capture.end()) --it;
    return static_cast<double>(it->second) - static_cast<double>(it->first - k) * 1e6 / 30.0;
  };
  std::vector<std::pair<int64_t, bool>> events;
  std::map<int64_t, int64_t> received_event;  // event frame → received
  for (const Received& r : got) {
    events.push_back({r.frame, r.state == protocol::RegionState::kEnter});
    received_event[r.frame] = r.received_us;
  }
  const std::vector<TrueEvent> transitions = TrueEvents(truth, *config, first, last);
  const Matched m = MatchEvents(transitions, events, last, window);
  // From the body's first contact (an exit's anchor is its volume crossing),
  // and from the frame its true volume crosses the threshold (what the
  // pipeline can answer).
  std::map<std::string, std::vector<double>> latency, latency_threshold;
  for (size_t i = 0; i < m.pairs.size(); ++i) {
    const char* kind = m.kinds_enter[i] ? "enter" : "leave";
    const auto received = static_cast<double>(received_event[m.pairs[i].second]);
    latency[kind].push_back((received - capture_of(m.pairs[i].first)) * 1e-3);
    latency_threshold[kind].push_back((received - capture_of(m.changes[i])) * 1e-3);
  }
  const auto& detect = m.frames;
  const int missed = m.missed, false_events = m.false_events;
  // What lies behind the tails: every event that took more than twice its
  // kind's detection median, and every reported event with no true change.
  for (size_t i = 0; i < m.pairs.size(); ++i) {
    const char* kind = m.kinds_enter[i] ? "enter" : "leave";
    const int64_t frames = m.pairs[i].second - m.pairs[i].first;
    if (static_cast<double>(frames) > 2.0 * Median(detect.at(kind)))
      progress(m.kinds_enter[i]
                   ? "slow enter: first true contact at frame " + std::to_string(m.pairs[i].first) +
                         ", the true volume over the threshold at frame " + std::to_string(m.changes[i]) +
                         ", event at frame " + std::to_string(m.pairs[i].second) + " (" + std::to_string(frames) +
                         " frames after the contact)"
                   : "slow leave: the true volume under the exit threshold at frame " +
                         std::to_string(m.changes[i]) + ", event at frame " + std::to_string(m.pairs[i].second) +
                         " (" + std::to_string(frames) + " frames)");
  }
  for (size_t e = 0; e < events.size(); ++e) {
    if (!m.used[e] && events[e].first <= last - window)
      progress(std::string("unmatched ") + (events[e].second ? "enter" : "leave") + " at frame " +
               std::to_string(events[e].first));
  }
  for (const auto& [kind, v] : latency) {
    auto q = q_fused;
    q["event"] = kind;
    q["n"] = std::to_string(v.size());
    auto emit_latency = [&](const char* from, const std::vector<double>& x) {
      for (const auto& [stat, f] : {std::pair{"p50", 0.5}, std::pair{"p99", 0.99}}) {
        auto y = q;
        y["from"] = from;
        y["stat"] = stat;
        EmitFigure("regions", wl, "event_latency_ms", InterpolatedQuantile(x, f), "ms", y);
      }
    };
    if (kind == "enter") emit_latency("contact", v);  // an exit is timed from its crossing only
    emit_latency("threshold", latency_threshold[kind]);
    EmitFigure("regions", wl, "detection_frames", Median(detect.at(kind)), "frames", q);
  }
  // The reports' own delay (capture of their frame → viewer): the site's
  // pipeline and the network, in the same run; an event's latency is this
  // plus the frames until the region's state changes.
  {
    std::vector<double> report_ms;
    for (const auto& [frame, at] : received_at) report_ms.push_back(static_cast<double>(at - capture[frame]) * 1e-3);
    auto q = q_fused;
    q["n"] = std::to_string(report_ms.size());
    EmitFigure("regions", wl, "report_latency_ms", InterpolatedQuantile(report_ms, 0.5), "ms", [&] { auto x = q; x["stat"] = "p50"; return x; }());
    EmitFigure("regions", wl, "report_latency_ms", InterpolatedQuantile(report_ms, 0.99), "ms", [&] { auto x = q; x["stat"] = "p99"; return x; }());
    EmitFigure("regions", wl, "site_fps", static_cast<double>(report_ms.size()) / o.seconds, "1/s", q_fused);
  }
  EmitFigure("regions", wl, "true_events", m.counted, "count", q_fused);
  EmitFigure("regions", wl, "missed_events", missed, "count", q_fused);
  EmitFigure("regions", wl, "false_events", false_events, "count", q_fused);
  EmitFigure("regions", wl, "reports_received", static_cast<double>(cs.regions_received), "count", q_fused);
  // The site's own figures: occupancy CPU per frame, frames fused.
  std::vector<double> cpu, wall;
  {
    std::ifstream f(stats_path);
    std::string line;
    while (std::getline(f, line)) {
      auto j = nlohmann::json::parse(line, nullptr, false);
      if (j.is_discarded() || !j.is_object() || !j.contains("regions_cpu_ms") || !j.contains("triangles")) continue;
      cpu.push_back(j["regions_cpu_ms"].get<double>());
      wall.push_back(j["regions_ms"].get<double>());
    }
  }
  if (!cpu.empty()) {
    auto q = q_fused;
    q["frames"] = std::to_string(cpu.size());
    EmitFigure("regions", wl, "regions_cpu_ms", Median(cpu), "ms", q);
    EmitFigure("regions", wl, "regions_ms", Median(wall), "ms", q);
  }
  if (o.keep_dir.empty()) std::system(("rm -rf '" + dir + "'").c_str());
  return latency.empty() ? 1 : 0;
}

BenchFn SetupRegions(CLI::App& app) {
  auto o = std::make_shared<RegionsBenchOptions>();
  DropCommonOptions(app, {"--repeats", "--frames"});
  app.add_option("--seconds", o->seconds, "seconds of reports to take after the site starts")
      ->check(CLI::Range(5.0, 3600.0))
      ->capture_default_str();
  app.add_option("--prerender", o->prerender, "frames the site pre-renders and loops forward and back")
      ->check(CLI::Range(30, 3000))
      ->capture_default_str();
  app.add_option("--site", o->site_binary, "holoport-server binary (default: next to this program)");
  app.add_option("--keep-dir", o->keep_dir, "keep the site's config, stats and log in this directory");
  return [o](const BenchArgs& args) { return RunRegionsBench(args, *o); };
}

}  // namespace

HOLO_REGISTER_BENCH_OPTIONS("regions",
                            "active regions end to end: a box the studio's person enters, fused live at 30 fps; "
                            "event latency (true entry → viewer), misses, false events, occupancy CPU-ms",
                            SetupRegions);

}  // namespace holo::bench
