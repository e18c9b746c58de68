// holoport-bench pods: distributed capture on one machine. Eight holoport-pod
// processes (one per camera, clocks offset by ±--offset-ms and drifting by up
// to ±--drift-ppm) stream to a site process started with --pods, paced at
// 30 fps on a shared trigger. Figures (content "fused": the site fuses what
// the pods sent): pod_mbps per pod (at 30 fps), sync_error_ms p50/p99 (spread
// of capture times within a set, after the offsets are taken out),
// sets_complete_fraction, site_fps, latency_p50_ms / latency_p99_ms from pod
// capture to textured mesh, and recovery_ms after one pod is killed for 3 s
// and restarted. The peer, measured in the same run: the same site with the
// frames in process (--prerender, paced at 30 fps), whose latency is
// acquisition → textured mesh. With --netns the pods run in their own network
// namespace behind a veth pair (and tc netem delay/loss where the kernel has
// it); the output says what was possible.
#include <arpa/inet.h>
#include <netinet/in.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <map>
#include <memory>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "bench.h"
#include "bench_process.h"
#include "common/log.h"
#include "common/quantile.h"
#include "common/status.h"
#include "net/wire_message.h"

namespace holo::bench {
namespace {

constexpr const char* kToken = "bench-pod-token";

struct PodsOptions {
  double warmup_s = 4;
  double seconds = 8;      // measured window
  double kill_s = 3;       // pod 0 down this long
  double after_s = 5;      // run on after the restart
  double offset_ms = 100;  // pods' clocks: ±offset (alternating sign)
  double drift_ppm = 50;   // ... and drift from −drift to +drift across pods
  int prerender = 20;
  double pod_timeout_ms = 60;  // the site's --pod-timeout-ms
  double fps = 30;             // the pods' trigger rate
  bool peer = true;
  bool netns = false;
  std::string netem = "delay 1ms 0.2ms loss 0.1%";
  std::string keep_dir;
};

int Sh(const std::string& cmd) { return std::system((cmd + " >/dev/null 2>&1").c_str()); }

// The pods' network namespace: a veth pair 10.77.0.1 (site) ↔ 10.77.0.2 (pods).
struct Netns {
  std::string name = "holo-bench-pods";
  bool up = false;
  std::string netem_status = "not tried";
  bool Setup(const std::string& netem) {
    Teardown();
    if (Sh("ip netns add " + name) != 0) return false;
    if (Sh("ip link add hbp0 type veth peer name hbp1") != 0 || Sh("ip link set hbp1 netns " + name) != 0 ||
        Sh("ip addr add 10.77.0.1/24 dev hbp0") != 0 || Sh("ip link set hbp0 up") != 0 ||
        Sh("ip netns exec " + name + " ip addr add 10.77.0.2/24 dev hbp1") != 0 ||
        Sh("ip netns exec " + name + " ip link set hbp1 up") != 0 ||
        Sh("ip netns exec " + name + " ip link set lo up") != 0) {
      Teardown();
      return false;
    }
    up = true;
    // Delay and loss both ways, where the kernel has sch_netem.
    const bool a = Sh("tc qdisc add dev hbp0 root netem " + netem) == 0;
    const bool b = Sh("ip netns exec " + name + " tc qdisc add dev hbp1 root netem " + netem) == 0;
    netem_status = a && b ? "netem " + netem : "tc netem unavailable (kernel has no sch_netem): no added delay or loss";
    return true;
  }
  void Teardown() {
    Sh("ip link del hbp0");
    Sh("ip netns del " + name);
    up = false;
  }
};

struct RunResult {
  std::vector<double> latency_ms;
  double site_fps = 0;
  double site_cpu_ms_per_frame = -1;
  bool ok = false;
};

// The in-process peer: the same site on pre-rendered frames, paced at 30 fps.
RunResult RunPeer(const BenchArgs& args, const PodsOptions& o, const std::string& dir, const std::string& server) {
  RunResult r;
  const std::string stats = dir + "/peer.jsonl";
  const pid_t pid = SpawnLogged({server, "--source", "synthetic", "--workload", args.workload, "--prerender",
                                  std::to_string(o.prerender), "--pace", "30", "--stats", stats, "-n", "-1"},
                                 dir + "/peer.log");
  // Background learning and pre-rendering first; then the warm-up and the window.
  auto frames_now = [&] {
    size_t n = 0;
    for (const auto& j : ReadJsonLines(stats))
      if (j.contains("latency_ms")) ++n;
    return n;
  };
  for (int i = 0; i < 1200 && frames_now() == 0; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(100));
  std::this_thread::sleep_for(std::chrono::duration<double>(o.warmup_s));
  const size_t n0 = frames_now();
  const double cpu0 = ProcessCpuMsOf(pid);
  const auto t0 = std::chrono::steady_clock::now();
  std::this_thread::sleep_for(std::chrono::duration<double>(o.seconds));
  const size_t n1 = frames_now();
  const double cpu1 = ProcessCpuMsOf(pid);
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  StopProcess(pid);
  size_t i = 0;
  for (const auto& j : ReadJsonLines(stats)) {
    if (!j.contains("latency_ms")) continue;
    if (i >= n0 && i < n1) r.latency_ms.push_back(j["latency_ms"].get<double>());
    ++i;
  }
  r.site_fps = static_cast<double>(n1 - n0) / wall;
  if (n1 > n0) r.site_cpu_ms_per_frame = (cpu1 - cpu0) / static_cast<double>(n1 - n0);
  r.ok = !r.latency_ms.empty();
  return r;
}

int RunPods(const BenchArgs& args, const PodsOptions& o) {
  const std::string bin = SelfDir();
  const std::string server = bin + "/holoport-server", pod_bin = bin + "/holoport-pod";
  for (const auto& p : {server, pod_bin})
    if (access(p.c_str(), X_OK) != 0) {
      spdlog::error("pods: {} not found (build holoport-server and holoport-pod)", p);
      return 2;
    }
  if (args.workload != "S8-QVGA" && args.workload != "S8-VGA") {
    spdlog::error("pods: --workload must be S8-QVGA or S8-VGA, got {}", args.workload);
    return 2;
  }
  std::string dir = o.keep_dir;
  if (dir.empty()) {
    char tmpl[] = "/tmp/holo-bench-pods-XXXXXX";
    if (!mkdtemp(tmpl)) return 1;
    dir = tmpl;
  } else if (Sh("mkdir -p '" + dir + "'") != 0) {
    return 1;
  }
  const std::string& W = args.workload;
  auto emit = [&](const std::string& metric, double v, const std::string& unit,
                  std::map<std::string, std::string> q = {}) {
    q.emplace("content", "fused");
    if (o.fps != 30) q.emplace("fps", std::to_string(static_cast<int>(o.fps)));
    EmitFigure("pods", W, metric, v, unit, q);
  };

  Netns ns;
  std::string site_host = "127.0.0.1", link = "loopback";
  if (o.netns) {
    if (ns.Setup(o.netem)) {
      site_host = "10.77.0.1";
      link = "netns";
    } else {
      link = "loopback (ip netns unavailable here)";
    }
  }

  // The peer first (the machine is quiet then), then the pods.
  RunResult peer;
  if (o.peer) {
    if (!args.json) spdlog::info("pods: in-process peer ({}, prerendered, paced at 30 fps)...", W);
    peer = RunPeer(args, o, dir, server);
  }

  const uint16_t port = FreeTcpPort();
  const std::string site_stats = dir + "/site.jsonl";
  if (!args.json) spdlog::info("pods: site on port {}, 8 pods ({})...", port, link);
  const pid_t site = SpawnLogged({server, "--workload", W, "--pods", (o.netns && ns.up ? "10.77.0.1:" : "127.0.0.1:") + std::to_string(port),
                                   "--pod-token", kToken, "--pod-set-stats", "--pod-timeout-ms", std::to_string(o.pod_timeout_ms),
                                   "--stats", site_stats, "-n", "-1"},
                                  dir + "/site.log");
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  const int kPods = 8;
  std::vector<double> offsets(kPods), drifts(kPods);
  std::vector<pid_t> pods(kPods, -1);
  auto pod_argv = [&](int k) {
    std::vector<std::string> a;
    if (ns.up) a = {"/usr/sbin/ip", "netns", "exec", ns.name};
    const std::vector<std::string> rest = {pod_bin, "--site", site_host + ":" + std::to_string(port), "--token", kToken,
                                           "--pod", std::to_string(k), "--workload", W, "--fps", std::to_string(o.fps), "--prerender",
                                           std::to_string(o.prerender), "--clock-offset-ms", std::to_string(offsets[k]),
                                           "--clock-drift-ppm", std::to_string(drifts[k]), "--stats",
                                           dir + "/pod" + std::to_string(k) + ".jsonl", "-q"};
    a.insert(a.end(), rest.begin(), rest.end());
    return a;
  };
  for (int k = 0; k < kPods; ++k) {
    offsets[k] = (k % 2 ? 1 : -1) * o.offset_ms * (0.5 + 0.5 * k / (kPods - 1.0));
    drifts[k] = o.drift_ppm * (2.0 * k / (kPods - 1.0) - 1.0);
    pods[k] = SpawnLogged(pod_argv(k), dir + "/pod" + std::to_string(k) + ".log");
  }
  // Wait for all eight pods to be connected and the site's pipeline to run.
  bool started = false;
  for (int i = 0; i < 1800 && !started; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    bool any_frame = false;
    int accepted = 0;
    for (const auto& j : ReadJsonLines(site_stats)) {
      if (j.contains("pod_hub")) accepted = j["accepted"].get<int>();
      if (j.contains("pod_frame")) any_frame = true;
    }
    started = accepted >= kPods && any_frame;
  }
  if (!started) {
    spdlog::error("pods: the site never fused a set from 8 connected pods (logs in {})", dir);
    for (pid_t p : pods) StopProcess(p);
    StopProcess(site);
    if (ns.up) ns.Teardown();
    return 1;
  }
  std::this_thread::sleep_for(std::chrono::duration<double>(o.warmup_s));
  const int64_t w0 = net::WallUs();
  const double site_cpu0 = ProcessCpuMsOf(site);
  std::this_thread::sleep_for(std::chrono::duration<double>(o.seconds));
  const int64_t w1 = net::WallUs();
  const double site_cpu1 = ProcessCpuMsOf(site);
  // One pod killed for kill_s, then restarted.
  StopProcess(pods[0], SIGKILL);
  const int64_t killed = net::WallUs();
  std::this_thread::sleep_for(std::chrono::duration<double>(o.kill_s));
  const int64_t restarted = net::WallUs();
  pods[0] = SpawnLogged(pod_argv(0), dir + "/pod0-restarted.log");
  std::this_thread::sleep_for(std::chrono::duration<double>(o.after_s));
  for (pid_t p : pods) StopProcess(p);
  StopProcess(site);
  if (ns.up) ns.Teardown();

  // Figures over the measured window [w0, w1).
  const auto all = ReadJsonLines(site_stats);
  std::vector<double> spread_ms, latency_ms;
  int64_t sets_in = 0, full_in = 0, frames_in = 0;
  int64_t first_back = -1;
  int64_t sets_while_down = 0, sets_down_complete = 0;
  std::map<int, nlohmann::json> last_pod;
  for (const auto& j : all) {
    if (j.contains("pod_set")) {
      const int64_t t = j["time_us"].get<int64_t>();
      const int present = j["present"].get<int>();
      if (t >= w0 && t < w1) {
        ++sets_in;
        if (present == kPods) ++full_in;
        if (present >= 2) spread_ms.push_back(static_cast<double>(j["spread_us"].get<int64_t>()) * 1e-3);
      }
      if (t > killed + 200000 && t < restarted) {
        ++sets_while_down;
        if (present == kPods - 1) ++sets_down_complete;
      }
      if (t > restarted && first_back < 0 && (j["pods_mask"].get<uint64_t>() & 1u))
        first_back = j["released_us"].get<int64_t>();
    } else if (j.contains("pod_frame")) {
      const int64_t c = j["capture_us"].get<int64_t>();
      if (c >= w0 && c < w1) {
        ++frames_in;
        latency_ms.push_back(j["capture_latency_ms"].get<double>());
      }
    } else if (j.contains("pod") && j.contains("received")) {
      last_pod[j["pod"].get<int>()] = j;
    }
  }
  const double window_s = static_cast<double>(w1 - w0) * 1e-6;
  for (int k = 0; k < kPods; ++k) {
    if (!last_pod.count(k)) continue;
    const auto& j = last_pod[k];
    const double received = j["received"].get<double>();
    // At 30 fps whatever the run's rate, as every bitrate of the project.
    const double mbps = received > 0 ? j["bytes"].get<double>() / received * 30.0 * 8.0 / 1e6 : 0;
    char off[32], dr[32];
    std::snprintf(off, sizeof off, "%.1f", offsets[k]);
    std::snprintf(dr, sizeof dr, "%.1f", drifts[k]);
    emit("pod_mbps", mbps, "Mbit/s", {{"pod", std::to_string(k)}, {"link", link}});
    emit("pod_offset_ms", j["offset_ms"].get<double>(), "ms",
         {{"pod", std::to_string(k)}, {"simulated_offset_ms", off}, {"simulated_drift_ppm", dr}});
    emit("pod_jitter_ms", j["jitter_ms"].get<double>(), "ms", {{"pod", std::to_string(k)}});
  }
  char stated[96];
  std::snprintf(stated, sizeof stated, "±%.0f ms offset, −%.0f..+%.0f ppm drift", o.offset_ms, o.drift_ppm, o.drift_ppm);
  emit("sync_error_p50_ms", InterpolatedQuantile(spread_ms, 0.50, -1), "ms", {{"clocks", stated}, {"link", link}});
  emit("sync_error_p99_ms", InterpolatedQuantile(spread_ms, 0.99, -1), "ms", {{"clocks", stated}, {"link", link}});
  char timeout_s[32];
  std::snprintf(timeout_s, sizeof timeout_s, "%.0f", o.pod_timeout_ms);
  emit("sets_complete_fraction", sets_in > 0 ? static_cast<double>(full_in) / static_cast<double>(sets_in) : 0, "1",
       {{"sets", std::to_string(sets_in)}, {"link", link}, {"pod_timeout_ms", timeout_s}});
  emit("sets_per_s", static_cast<double>(sets_in) / window_s, "1/s", {{"link", link}});
  emit("site_fps", static_cast<double>(frames_in) / window_s, "1/s", {{"mode", "pods"}, {"link", link}});
  if (frames_in > 0)
    emit("site_cpu_ms_per_frame", (site_cpu1 - site_cpu0) / static_cast<double>(frames_in), "ms", {{"mode", "pods"}});
  emit("latency_p50_ms", InterpolatedQuantile(latency_ms, 0.50, -1), "ms", {{"mode", "pods"}, {"from", "pod capture"}, {"to", "textured mesh"}});
  emit("latency_p99_ms", InterpolatedQuantile(latency_ms, 0.99, -1), "ms", {{"mode", "pods"}, {"from", "pod capture"}, {"to", "textured mesh"}});
  emit("recovery_ms", first_back > 0 ? static_cast<double>(first_back - restarted) * 1e-3 : -1, "ms",
       {{"from", "restarted pod process spawned (pre-renders " + std::to_string(o.prerender) + " frames)"},
        {"to", "first set with that pod"}, {"down_s", std::to_string(static_cast<int>(o.kill_s))}});
  emit("sets_complete_fraction_while_down", sets_while_down > 0 ? static_cast<double>(sets_down_complete) / static_cast<double>(sets_while_down) : 0,
       "1", {{"sets", std::to_string(sets_while_down)}, {"note", "sets with the 7 remaining pods"}});
  if (o.netns) emit("netns", ns.netem_status.empty() ? 0 : (link == "netns" ? 1 : 0), "1", {{"status", link == "netns" ? ns.netem_status : link}});
  if (o.peer && peer.ok) {
    emit("site_fps", peer.site_fps, "1/s", {{"mode", "in-process"}, {"peer", "in-process"}});
    if (peer.site_cpu_ms_per_frame > 0)
      emit("site_cpu_ms_per_frame", peer.site_cpu_ms_per_frame, "ms", {{"mode", "in-process"}, {"peer", "in-process"}});
    const double p50 = InterpolatedQuantile(peer.latency_ms, 0.50, -1), p99 = InterpolatedQuantile(peer.latency_ms, 0.99, -1);
    emit("latency_p50_ms", p50, "ms", {{"mode", "in-process"}, {"peer", "in-process"}, {"from", "acquisition"}, {"to", "textured mesh"}});
    emit("latency_p99_ms", p99, "ms", {{"mode", "in-process"}, {"peer", "in-process"}, {"from", "acquisition"}, {"to", "textured mesh"}});
    emit("latency_p50_diff_ms", InterpolatedQuantile(latency_ms, 0.50, -1) - p50, "ms", {{"peer", "in-process"}, {"target", "<= 15"}});
  }
  if (!args.json) spdlog::info("pods: logs and stats in {}", dir);
  if (o.keep_dir.empty()) Sh("rm -rf '" + dir + "'");
  return 0;
}

BenchFn SetupPods(CLI::App& app) {
  DropCommonOptions(app, {"--frames", "--repeats"});  // this benchmark does not read them
  auto o = std::make_shared<PodsOptions>();
  app.add_option("--warmup", o->warmup_s, "seconds after the first full set before measuring")->check(CLI::Range(0.0, 60.0));
  app.add_option("--seconds", o->seconds, "measured window, s")->check(CLI::Range(2.0, 600.0));
  app.add_option("--kill-seconds", o->kill_s, "pod 0 is killed this long after the window, then restarted")
      ->check(CLI::Range(0.5, 60.0));
  app.add_option("--offset-ms", o->offset_ms, "pods' clock offsets: up to ±this")->check(CLI::Range(0.0, 10000.0));
  app.add_option("--drift-ppm", o->drift_ppm, "pods' clock drifts: −this..+this")->check(CLI::Range(0.0, 1000.0));
  app.add_option("--prerender", o->prerender, "frames each pod renders first and loops")->check(CLI::Range(2, 300));
  app.add_option("--fps", o->fps, "the pods' trigger rate (30: the workloads' rate)")->check(CLI::Range(1.0, 60.0));
  app.add_option("--pod-timeout-ms", o->pod_timeout_ms, "the site's --pod-timeout-ms")->check(CLI::Range(0.0, 2000.0));
  app.add_flag("--no-peer", [o](int64_t) { o->peer = false; }, "skip the in-process peer run");
  app.add_flag("--netns", o->netns, "run the pods in their own network namespace (veth; tc netem where available)");
  app.add_option("--netem", o->netem, "netem arguments for --netns")->capture_default_str();
  app.add_option("--keep", o->keep_dir, "keep logs and stats in this directory");
  return [o](const BenchArgs& args) { return RunPods(args, *o); };
}

HOLO_REGISTER_BENCH_OPTIONS("pods",
                            "distributed capture: 8 holoport-pod processes and a site on loopback at 30 fps; Mbit/s "
                            "per pod, sync error, complete sets, latency vs the in-process site, recovery of a "
                            "restarted pod",
                            SetupPods);

}  // namespace
}  // namespace holo::bench
