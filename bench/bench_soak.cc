// holoport-bench soak: a two-site call left running for many minutes, to find
// what only time shows: memory that grows, a program that slows down, errors.
//
//   holoport-bench soak --minutes M [--viewers N] [--pace FPS] [--json]
//
// Processes, each its own program from holoport-bench's directory, on loopback:
//   site-a, site-b  holoport-server: the real capture pipeline (segmentation,
//                   fusion, stream mesh, G1 + C1) on pre-rendered pod frames of
//                   --workload paced at --pace fps (content "fused"), each
//                   with its session server;
//   alice, bob      holoport-call --config: the call's participants. Each
//                   publishes a voice (Opus 20 ms frames of a tone with a
//                   moving head pose) to its own site and watches and hears
//                   the other site (decode, jitter buffer; with --aec on, the
//                   default, also the HRTF spatializer and the echo canceller);
//   recorder        holoport-record --connect site-a --out FILE;
//   viewer-K        holoport-call --watch: decode-only viewers, alternating
//                   between the two sites.
// The programs report through their own outputs: the sites' --stats JSON
// lines (one per published frame, CPU per frame every 30 frames, session
// counters), holoport-call's --stats lines (one per second: frames and their
// latencies, the client's and the call's counters), and their logs. RSS
// (/proc/PID/status VmRSS) and CPU of every process are sampled every second
// (samples.jsonl in the run's directory: t_s from the measured run's start,
// load, rss_mb and cpu_ms per process).
//
// The run: sites start, then the clients; once every client receives frames
// (and each participant hears the other) and --warmup seconds have passed,
// the measured run of --minutes starts. It is cut into windows of
// W = min(60 s, run / 3) ("minutes"); one progress line per window in the
// log (info level, also with --json: a long run shows that it is alive).
//
// Figures (JSON lines, content "fused", "process" names the program):
//   rss_mb (at the end of the first window and at the end), rss_growth_pct
//   (median RSS of the last 10 s against that around the end of the first
//   window), rss_slope_mb_per_h (least squares after the first window);
//   fps and latency_p50_ms / latency_p99_ms in the first and the last window
//   (sites: frames published, capture → encoded; clients: frames received,
//   capture → decoded and taken by the program), cpu_ms_per_frame of the sites
//   per window, cpu_pct per process; audio_underruns (the participants'
//   jitter buffers: pulls with nothing to play), audio_concealed,
//   audio_heard_fraction; errors by kind (process exits, exits at shutdown
//   that were not clean, reconnections, decode errors, session refusals and
//   protocol violations counted by the sites, error lines in the logs, a
//   recording that does not validate); load_avg per window; then one
//   target_met line per target and soak_pass.
// Targets: RSS growth ≤ --rss-target-pct (5) per process; fps not lower and
// latency p99 not higher in the last window than in the first beyond the
// noise (max(10 % of fps / 20 % of latency, twice the window-to-window noise
// estimated from successive differences over the run); zero errors.
// Exit: 0 all targets met, 1 a target missed or the run failed, 2 bad
// options, 130 interrupted (Ctrl-C / SIGTERM: every child is stopped, the
// figures of the part that ran are printed).
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <map>
#include <memory>
#include <sstream>
#include <string>
#include <thread>
#include <tuple>
#include <vector>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "bench.h"
#include "bench_process.h"
#include "common/log.h"
#include "common/quantile.h"

namespace holo::bench {
namespace {

struct SoakOptions {
  double minutes = 30;
  int viewers = 2;
  // Each site's camera rate. Two fused sites, two participants, a recorder and
  // the viewers share the machine's cores: at 10 fps a site on a loaded 2-core
  // machine fell behind (4.5 fps, 1.5 s of queueing), and a soak should
  // measure the programs, not the queue of a saturated machine.
  double pace = 5;
  int prerender = 30;
  bool aec = true;
  double warmup_s = 15;
  double start_timeout_s = 300;
  double rss_target_pct = 5;
  std::string keep_dir;
  std::vector<std::string> site_args;
};

std::atomic<bool> g_interrupted{false};
void OnSoakSignal(int) { g_interrupted = true; }

// Sleeps `s` seconds in short steps; false if interrupted.
bool SleepS(double s) {
  const double until = WallS() + s;
  while (WallS() < until) {
    if (g_interrupted) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(std::min<int>(100, static_cast<int>((until - WallS()) * 1e3) + 1)));
  }
  return !g_interrupted;
}

// The complete lines appended to a file since the last call.
class LineTail {
 public:
  void SetPath(std::string path) { path_ = std::move(path); }
  std::vector<std::string> Next() {
    std::vector<std::string> lines;
    std::ifstream f(path_, std::ios::binary);
    if (!f) return lines;
    f.seekg(static_cast<std::streamoff>(offset_));
    std::string chunk((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
    offset_ += chunk.size();
    pending_ += chunk;
    size_t start = 0;
    for (size_t nl; (nl = pending_.find('\n', start)) != std::string::npos; start = nl + 1)
      lines.push_back(pending_.substr(start, nl - start));
    pending_.erase(0, start);
    return lines;
  }

 private:
  std::string path_;
  uint64_t offset_ = 0;
  std::string pending_;
};

// VmRSS of `pid`, MB; < 0 when the process is gone.
double RssMbOf(pid_t pid) {
  std::ifstream f("/proc/" + std::to_string(pid) + "/status");
  std::string line;
  while (std::getline(f, line)) {
    if (line.rfind("VmRSS:", 0) == 0) return std::atof(line.c_str() + 6) / 1024.0;  // kB
  }
  return -1;
}

double LoadAvg1() {
  std::ifstream f("/proc/loadavg");
  double l = -1;
  f >> l;
  return l;
}

// One --stats line of holoport-call.
struct CallLine {
  double t = 0;  // wall seconds
  std::vector<double> latency_ms;
  std::string state;
  int64_t connects = 0, decode_errors = 0, dropped_local = 0;
  int64_t voice_sent = 0, audio_heard = 0, concealed = 0, late = 0, underflows = 0;
};

struct Sample {
  double t = 0, value = 0;
};

enum class Kind { kSite, kParticipant, kRecorder, kViewer };

struct Proc {
  std::string name;
  Kind kind = Kind::kSite;
  std::vector<std::string> argv;
  std::string log_path, stats_path;
  pid_t pid = -1;
  bool running = false;
  int exit_status = 0;
  LineTail stats_tail, log_tail;
  std::vector<Sample> rss_mb, cpu_ms;
  // Sites: one sample per published frame (t read, capture → encoded ms),
  // CPU per frame lines, session counters (latest).
  std::vector<Sample> frames;
  std::vector<Sample> site_cpu_per_frame;
  int64_t refused = 0, violations = 0, fanout_dropped = 0, fanout_sent = 0;
  // Clients.
  std::vector<CallLine> lines;
  bool recorder_connected = false;
  // Errors by kind, with the first example of each.
  std::map<std::string, int64_t> errors;
  std::map<std::string, std::string> error_example;

  void AddError(const std::string& kind, const std::string& example, int64_t n = 1) {
    if (n <= 0) return;
    errors[kind] += n;
    if (!error_example.count(kind)) error_example[kind] = example.substr(0, 300);
  }
  bool IsClient() const { return kind != Kind::kSite; }
};

std::string Lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

// A log line that reports a fault. Before shutdown also a session that closed
// or a client that lost its site (a disconnection); during shutdown those are
// expected and only crashes count.
bool IsErrorLine(const std::string& line, bool shutting_down) {
  const std::string l = Lower(line);
  for (const char* w : {"fatal", "abort", "sanitizer", "terminate called", "exception", "segmentation fault",
                        "core dumped", "leak"}) {
    if (l.find(w) != std::string::npos) return true;
  }
  if (shutting_down) return false;
  for (const char* w : {"error", "fail", "closed", "retrying", "backoff", "refused", "violation", "reconnect"}) {
    if (l.find(w) != std::string::npos) return true;
  }
  return false;
}

std::string DescribeStatus(int status) {
  if (WIFEXITED(status)) return "exit code " + std::to_string(WEXITSTATUS(status));
  if (WIFSIGNALED(status)) return std::string("killed by signal ") + strsignal(WTERMSIG(status));
  return "status " + std::to_string(status);
}

class Soak {
 public:
  Soak(const BenchArgs& args, const SoakOptions& o) : args_(args), o_(o) {}
  ~Soak() { StopAll(); }

  int Run();

 private:
  void Say(const std::string& s) const {
    if (!args_.json) spdlog::info("soak: {}", s);
  }
  bool Spawn(Proc* p) {
    p->pid = SpawnLogged(p->argv, p->log_path, /*tied=*/true);
    p->running = p->pid > 0;
    p->log_tail.SetPath(p->log_path);
    if (!p->stats_path.empty()) p->stats_tail.SetPath(p->stats_path);
    if (!p->running) spdlog::error("soak: cannot start {}", p->argv[0]);
    return p->running;
  }
  void SampleAll();
  void Read(Proc* p);
  void StopGroup(const std::vector<Proc*>& group);
  void StopAll();
  bool WaitUntil(const std::string& what, double timeout_s, const std::function<bool()>& ready);
  void Progress(int window, int windows, double w0, double w1);
  int Report(double t_end, bool interrupted);

  const BenchArgs& args_;
  const SoakOptions& o_;
  std::string dir_, bin_;
  std::vector<std::unique_ptr<Proc>> procs_;
  std::vector<Sample> load_;
  std::unique_ptr<FILE, int (*)(FILE*)> samples_{nullptr, &std::fclose};
  bool shutting_down_ = false;
  double t0_ = 0;  // start of the measured run (wall s)
  std::string recording_;
};

void Soak::Read(Proc* p) {
  const double now = WallS();
  for (const std::string& line : p->log_tail.Next()) {
    if (IsErrorLine(line, shutting_down_)) p->AddError("log", line);
    if (p->kind == Kind::kRecorder && line.find("connected to") != std::string::npos) p->recorder_connected = true;
  }
  for (const std::string& line : p->stats_tail.Next()) {
    const auto j = nlohmann::json::parse(line, nullptr, /*allow_exceptions=*/false);
    if (j.is_discarded() || !j.is_object()) continue;
    if (p->kind == Kind::kSite) {
      if (j.contains("triangles")) {
        p->frames.push_back({now, j.value("encoded_latency_ms", j.value("latency_ms", 0.0))});
      } else if (j.value("net", false)) {
        // Sums over the sessions open now (the line written at exit has none): keep the largest.
        p->refused = std::max(p->refused, j.value("refused", int64_t{0}));
        p->violations = std::max(p->violations, j.value("violations", int64_t{0}));
        p->fanout_dropped = std::max(p->fanout_dropped, j.value("frames_dropped", int64_t{0}));
        p->fanout_sent = std::max(p->fanout_sent, j.value("frames_sent", int64_t{0}));
      } else if (j.value("site", false)) {
        p->site_cpu_per_frame.push_back({now, j.value("cpu_ms_per_frame", 0.0)});
      }
      continue;
    }
    CallLine c;
    c.t = j.value("wall_us", int64_t{0}) * 1e-6;
    if (j.contains("latency_ms") && j["latency_ms"].is_array())
      for (const auto& v : j["latency_ms"])
        if (v.is_number()) c.latency_ms.push_back(v.get<double>());
    c.state = j.value("state", std::string());
    c.connects = j.value("connects", int64_t{0});
    c.decode_errors = j.value("decode_errors", int64_t{0});
    c.dropped_local = j.value("frames_dropped_local", int64_t{0});
    c.voice_sent = j.value("voice_sent", int64_t{0});
    c.audio_heard = j.value("audio_heard", int64_t{0});
    c.concealed = j.value("concealed", int64_t{0});
    c.late = j.value("late", int64_t{0});
    c.underflows = j.value("underflows", int64_t{0});
    p->lines.push_back(std::move(c));
  }
}

void Soak::SampleAll() {
  const double now = WallS();
  load_.push_back({now, LoadAvg1()});
  nlohmann::ordered_json line;  // samples.jsonl: the series behind the figures, for a closer look
  line["t_s"] = t0_ > 0 ? now - t0_ : 0.0;
  line["load"] = load_.back().value;
  for (auto& up : procs_) {
    Proc* p = up.get();
    if (p->running) {
      const double rss = RssMbOf(p->pid), cpu = ProcessCpuMsOf(p->pid);
      if (rss > 0) p->rss_mb.push_back({now, rss});
      if (cpu >= 0) p->cpu_ms.push_back({now, cpu});
      line["rss_mb"][p->name] = rss;
      line["cpu_ms"][p->name] = cpu;
      int status = 0;
      if (waitpid(p->pid, &status, WNOHANG) == p->pid) {
        p->running = false;
        p->exit_status = status;
        if (!shutting_down_) p->AddError("exit", p->name + " stopped during the run: " + DescribeStatus(status));
      }
    }
    Read(p);
  }
  if (!samples_) samples_.reset(std::fopen((dir_ + "/samples.jsonl").c_str(), "w"));
  if (samples_) {
    std::fprintf(samples_.get(), "%s\n", line.dump().c_str());
    std::fflush(samples_.get());
  }
}

void Soak::StopGroup(const std::vector<Proc*>& group) {
  for (Proc* p : group)
    if (p->running) kill(p->pid, SIGTERM);
  const double deadline = WallS() + 20;
  for (;;) {
    bool any = false;
    for (Proc* p : group) {
      if (!p->running) continue;
      int status = 0;
      if (waitpid(p->pid, &status, WNOHANG) == p->pid) {
        p->running = false;
        p->exit_status = status;
        if (!WIFEXITED(status) || WEXITSTATUS(status) != 0)
          p->AddError("shutdown", p->name + " did not stop cleanly on SIGTERM: " + DescribeStatus(status));
      } else {
        any = true;
      }
    }
    if (!any) break;
    if (WallS() > deadline) {
      for (Proc* p : group) {
        if (!p->running) continue;
        kill(p->pid, SIGKILL);
        waitpid(p->pid, &p->exit_status, 0);
        p->running = false;
        p->AddError("shutdown", p->name + " still running 20 s after SIGTERM: killed");
      }
      break;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
}

// Clients first (so the sites see orderly goodbyes), then the sites.
void Soak::StopAll() {
  shutting_down_ = true;
  std::vector<Proc*> clients, sites;
  for (auto& p : procs_) (p->IsClient() ? clients : sites).push_back(p.get());
  StopGroup(clients);
  StopGroup(sites);
}

bool Soak::WaitUntil(const std::string& what, double timeout_s, const std::function<bool()>& ready) {
  const double until = WallS() + timeout_s;
  while (!g_interrupted) {
    SampleAll();
    if (ready()) return true;
    for (auto& p : procs_) {
      if (!p->running) {
        spdlog::error("soak: {} exited while waiting for {} ({}; log {})", p->name, what,
                      DescribeStatus(p->exit_status), p->log_path);
        return false;
      }
    }
    if (WallS() > until) {
      spdlog::error("soak: no {} within {:.0f} s (logs in {})", what, timeout_s, dir_);
      return false;
    }
    SleepS(0.5);
  }
  return false;
}

// Frames, latencies and CPU of one process in [w0, w1).
struct WindowFigures {
  double fps = 0, p50 = 0, p99 = 0, cpu_ms_per_frame = 0;
  int64_t frames = 0;
};

double ValueAt(const std::vector<Sample>& s, double t) {  // the last sample at or before t (else the first after)
  double v = s.empty() ? 0 : s.front().value;
  for (const Sample& x : s) {
    if (x.t > t) break;
    v = x.value;
  }
  return v;
}

WindowFigures Figures(const Proc& p, double w0, double w1) {
  WindowFigures f;
  std::vector<double> lat;
  if (p.kind == Kind::kSite) {
    for (const Sample& s : p.frames)
      if (s.t >= w0 && s.t < w1) lat.push_back(s.value);
    f.frames = static_cast<int64_t>(lat.size());
    const double cpu = ValueAt(p.cpu_ms, w1) - ValueAt(p.cpu_ms, w0);
    f.cpu_ms_per_frame = f.frames > 0 ? cpu / static_cast<double>(f.frames) : 0;
  } else {
    for (const CallLine& c : p.lines)
      if (c.t >= w0 && c.t < w1) lat.insert(lat.end(), c.latency_ms.begin(), c.latency_ms.end());
    f.frames = static_cast<int64_t>(lat.size());
  }
  f.fps = static_cast<double>(f.frames) / std::max(1e-3, w1 - w0);
  f.p50 = InterpolatedQuantile(lat, 0.50);
  f.p99 = InterpolatedQuantile(lat, 0.99);
  return f;
}

double MedianIn(const std::vector<Sample>& s, double t0, double t1) {
  std::vector<double> v;
  for (const Sample& x : s)
    if (x.t >= t0 && x.t <= t1) v.push_back(x.value);
  return Median(v);
}

// Least-squares slope of the samples in [t0, t1], per hour.
double SlopePerHour(const std::vector<Sample>& s, double t0, double t1) {
  double n = 0, st = 0, sv = 0, stt = 0, stv = 0;
  for (const Sample& x : s) {
    if (x.t < t0 || x.t > t1) continue;
    const double t = x.t - t0;
    n += 1, st += t, sv += x.value, stt += t * t, stv += t * x.value;
  }
  const double d = n * stt - st * st;
  return n >= 3 && d > 0 ? 3600.0 * (n * stv - st * sv) / d : 0;
}

// Window-to-window noise of a series: sqrt(mean squared successive difference / 2),
// which a slow trend barely moves (von Neumann).
double SuccessiveNoise(const std::vector<double>& v) {
  if (v.size() < 3) return 0;
  double s = 0;
  for (size_t i = 1; i < v.size(); ++i) s += (v[i] - v[i - 1]) * (v[i] - v[i - 1]);
  return std::sqrt(s / (2.0 * static_cast<double>(v.size() - 1)));
}

// The latest CallLine at or before t (nullptr if none).
const CallLine* LineAt(const Proc& p, double t) {
  const CallLine* c = nullptr;
  for (const CallLine& x : p.lines) {
    if (x.t > t) break;
    c = &x;
  }
  return c;
}

void Soak::Progress(int window, int windows, double w0, double w1) {
  std::ostringstream s;
  char buf[160];
  std::snprintf(buf, sizeof buf, "soak: %d/%d (%.1f min): ", window + 1, windows, (w1 - t0_) / 60.0);
  s << buf;
  int64_t errors = 0;
  for (auto& p : procs_) {
    const WindowFigures f = Figures(*p, w0, w1);
    for (const auto& [k, n] : p->errors) errors += n;
    const double rss = p->rss_mb.empty() ? 0 : p->rss_mb.back().value;
    if (p->kind == Kind::kRecorder) {
      std::snprintf(buf, sizeof buf, "%s %.0f MB; ", p->name.c_str(), rss);
    } else {
      std::snprintf(buf, sizeof buf, "%s %.1f fps p99 %.0f ms %.0f MB; ", p->name.c_str(), f.fps, f.p99, rss);
    }
    s << buf;
  }
  std::snprintf(buf, sizeof buf, "errors %lld, load %.1f", static_cast<long long>(errors), ValueAt(load_, w1));
  s << buf;
  spdlog::info("{}", s.str());
}

int Soak::Run() {
  bin_ = SelfDir();
  for (const char* prog : {"holoport-server", "holoport-call", "holoport-record"}) {
    if (access((bin_ + "/" + prog).c_str(), X_OK) != 0) {
      spdlog::error("soak: {}/{} not found (build it: cmake --build build --target {})", bin_, prog, prog);
      return 2;
    }
  }
  dir_ = o_.keep_dir;
  if (dir_.empty()) {
    char tmpl[] = "/tmp/holoport-soak-XXXXXX";
    if (!mkdtemp(tmpl)) {
      spdlog::error("soak: cannot make a temporary directory");
      return 1;
    }
    dir_ = tmpl;
  } else if (std::error_code ec; !std::filesystem::create_directories(dir_, ec) && ec) {
    spdlog::error("soak: cannot make {}: {}", dir_, ec.message());
    return 1;
  }
  const uint16_t port_a = FreeTcpPort();
  uint16_t port_b = FreeTcpPort();
  while (port_b == port_a) port_b = FreeTcpPort();
  const std::string addr_a = "127.0.0.1:" + std::to_string(port_a), addr_b = "127.0.0.1:" + std::to_string(port_b);

  auto add = [&](const std::string& name, Kind kind, std::vector<std::string> argv, bool stats) {
    auto p = std::make_unique<Proc>();
    p->name = name;
    p->kind = kind;
    p->log_path = dir_ + "/" + name + ".log";
    if (stats) p->stats_path = dir_ + "/" + name + ".jsonl";
    p->argv = std::move(argv);
    if (stats) p->argv.insert(p->argv.end(), {"--stats", p->stats_path});
    procs_.push_back(std::move(p));
    return procs_.back().get();
  };
  // 1. The two sites.
  std::vector<Proc*> sites;
  for (const auto& [name, addr, room] : {std::tuple{"site-a", addr_a, "a"}, std::tuple{"site-b", addr_b, "b"}}) {
    std::vector<std::string> a = {bin_ + "/holoport-server", "--source", "synthetic", "--workload", args_.workload,
                                  "--prerender", std::to_string(o_.prerender), "--pace", std::to_string(o_.pace),
                                  "-n", "-1", "--listen", addr, "--publisher-token",
                                  std::string("soak-") + room + "-pub", "--viewer-token",
                                  std::string("soak-") + room + "-view"};
    a.insert(a.end(), o_.site_args.begin(), o_.site_args.end());
    sites.push_back(add(name, Kind::kSite, a, true));
  }
  char pace[32];
  std::snprintf(pace, sizeof pace, "%g", o_.pace);
  Say("sites (fused, " + args_.workload + ", " + std::to_string(o_.prerender) + " pre-rendered frame sets at " +
      pace + " fps) on " + addr_a + " and " + addr_b + "; logs in " + dir_);
  for (Proc* p : sites)
    if (!Spawn(p)) return 1;
  if (!WaitUntil("frames from both sites", o_.start_timeout_s, [&] {
        return !sites[0]->frames.empty() && !sites[1]->frames.empty();
      }))
    return g_interrupted ? 130 : 1;

  // 2. The participants, the recorder, the viewers.
  auto write_call = [&](const std::string& who, const std::string& local_addr, const std::string& local,
                        const std::string& remote_addr, const std::string& remote) {
    const std::string path = dir_ + "/" + who + ".yaml";
    std::ofstream f(path);
    f << "local:  {name: site-" << local << ", address: " << local_addr << ", publisher_token: soak-" << local
      << "-pub}\n"
      << "remote: {name: site-" << remote << ", address: " << remote_addr << ", viewer_token: soak-" << remote
      << "-view}\n"
      << "room:   {preset: face-to-face, gap_m: 0.5}\n";
    return path;
  };
  std::vector<Proc*> clients;
  const std::string aec = o_.aec ? "on" : "off";
  clients.push_back(add("alice", Kind::kParticipant,
                        {bin_ + "/holoport-call", "--config", write_call("alice", addr_a, "a", addr_b, "b"), "--name",
                         "alice", "--aec", aec},
                        true));
  clients.push_back(add("bob", Kind::kParticipant,
                        {bin_ + "/holoport-call", "--config", write_call("bob", addr_b, "b", addr_a, "a"), "--name",
                         "bob", "--aec", aec},
                        true));
  recording_ = dir_ + "/site-a.hrec";
  clients.push_back(add("recorder", Kind::kRecorder,
                        {bin_ + "/holoport-record", "--connect", addr_a, "--token", "soak-a-view", "--out", recording_,
                         "--overwrite", "--connect-timeout", "60"},
                        false));
  for (int i = 0; i < o_.viewers; ++i) {
    const bool a = i % 2 == 0;
    clients.push_back(add("viewer-" + std::to_string(i + 1), Kind::kViewer,
                          {bin_ + "/holoport-call", "--watch", a ? addr_a : addr_b, "--token",
                           a ? "soak-a-view" : "soak-b-view", "--name", "viewer-" + std::to_string(i + 1)},
                          true));
  }
  Say("starting the participants (alice: site-a, bob: site-b; --aec " + aec + "), the recorder of site-a and " +
      std::to_string(o_.viewers) + " decode-only viewers");
  for (Proc* p : clients)
    if (!Spawn(p)) return 1;
  if (!WaitUntil("frames at every client and voice both ways", 120, [&] {
        for (Proc* p : clients) {
          if (p->kind == Kind::kRecorder) {
            if (!p->recorder_connected) return false;
            continue;
          }
          if (p->lines.empty() || p->lines.back().connects < 1) return false;
          int64_t frames = 0;
          for (const CallLine& c : p->lines) frames += static_cast<int64_t>(c.latency_ms.size());
          if (frames == 0) return false;
          if (p->kind == Kind::kParticipant && p->lines.back().audio_heard == 0) return false;
        }
        return true;
      }))
    return g_interrupted ? 130 : 1;
  Say("all connected; warming up " + std::to_string(static_cast<int>(o_.warmup_s)) + " s");
  const double warm_until = WallS() + o_.warmup_s;
  while (WallS() < warm_until && !g_interrupted) {
    SampleAll();
    SleepS(1);
  }

  // 3. The measured run, one sample a second.
  const double run_s = o_.minutes * 60.0;
  const double w = std::min(60.0, run_s / 3.0);
  const int windows = static_cast<int>(std::floor(run_s / w + 1e-6));
  t0_ = WallS();
  spdlog::info("soak: measuring {:.1f} min (windows of {:.0f} s); Ctrl-C stops early and reports", o_.minutes, w);
  int window = 0;
  double next = t0_;
  while (!g_interrupted && window < windows) {
    SampleAll();
    const double now = WallS();
    if (now >= t0_ + (window + 1) * w) {
      Progress(window, windows, t0_ + window * w, t0_ + (window + 1) * w);
      ++window;
    }
    next += 1.0;
    if (window < windows) SleepS(std::max(0.0, std::min(next, t0_ + window * w + w) - WallS()));
  }
  const double t_end = WallS();
  SampleAll();
  const bool interrupted = g_interrupted;
  if (interrupted) spdlog::warn("soak: interrupted after {:.1f} min; stopping every process", (t_end - t0_) / 60);
  StopAll();
  for (auto& p : procs_) Read(p.get());  // the last lines written at exit
  const int code = Report(t_end, interrupted);
  for (auto& p : procs_)
    if (p->running) spdlog::error("soak: {} (pid {}) is still running", p->name, p->pid);
  return interrupted ? 130 : code;
}

int Soak::Report(double t_end, bool interrupted) {
  const std::string& wl = args_.workload;
  auto emit = [&](const std::string& metric, double value, const std::string& unit,
                  std::map<std::string, std::string> q = {}) {
    q["content"] = "fused";
    EmitFigure("soak", wl, metric, value, unit, q);
  };
  const double run_s = t_end - t0_;
  if (run_s < 3) {
    spdlog::error("soak: the run lasted {:.1f} s: no figures", run_s);
    return 1;
  }
  // An interrupted run is cut into windows of its own length.
  const double w = std::min(60.0, std::min(o_.minutes * 60.0, run_s) / 3.0);
  const int windows = std::max(1, static_cast<int>(std::floor(run_s / w + 1e-6)));
  const double first0 = t0_, first1 = t0_ + w, last0 = t_end - w, last1 = t_end;
  char fmt[64];
  auto num = [&](double v) {
    std::snprintf(fmt, sizeof fmt, "%.4g", v);
    return std::string(fmt);
  };
  emit("run_minutes", run_s / 60.0, "min",
       {{"window_s", num(w)}, {"windows", std::to_string(windows)}, {"interrupted", interrupted ? "yes" : "no"},
        {"pace_fps", num(o_.pace)}, {"viewers", std::to_string(o_.viewers)}});
  emit("load_avg", MedianIn(load_, first0, first1), "1-min load", {{"window", "first"}});
  emit("load_avg", MedianIn(load_, last0, last1), "1-min load", {{"window", "last"}});
  emit("load_avg", MedianIn(load_, first0, last1), "1-min load", {{"window", "run"}, {"cores", std::to_string(sysconf(_SC_NPROCESSORS_ONLN))}});

  struct Check {
    explicit Check(std::string t) : target(std::move(t)) {}
    std::string target;
    bool met = true;
    std::string worst_process;
    double worst = 0;
  };
  Check rss_check{"rss_growth_pct <= " + num(o_.rss_target_pct)};
  Check fps_check{"fps last window >= first - max(10%, 2 noise)"};
  Check lat_check{"latency_p99 last window <= first + max(20%, 2 noise)"};
  Check err_check{"errors == 0"};
  bool first_rss = true, first_fps = true, first_lat = true;
  int64_t total_errors = 0;

  for (auto& up : procs_) {
    const Proc& p = *up;
    const std::map<std::string, std::string> q = {{"process", p.name}};
    auto with = [&](std::map<std::string, std::string> extra) {
      extra["process"] = p.name;
      return extra;
    };
    // Memory.
    const double span = std::min(5.0, w / 4.0);
    const double rss_first = MedianIn(p.rss_mb, first1 - span, first1 + span);
    const double rss_end = MedianIn(p.rss_mb, t_end - 2 * span, t_end);
    const double growth = rss_first > 0 ? 100.0 * (rss_end - rss_first) / rss_first : 0;
    emit("rss_mb", rss_first, "MB", with({{"at", "end of first window"}}));
    emit("rss_mb", rss_end, "MB", with({{"at", "end"}}));
    emit("rss_growth_pct", growth, "%", with({{"from", "end of first window"}, {"to", "end"}}));
    emit("rss_slope_mb_per_h", SlopePerHour(p.rss_mb, first1, t_end), "MB/h", with({{"from", "end of first window"}}));
    if (first_rss || growth > rss_check.worst) rss_check.worst = growth, rss_check.worst_process = p.name;
    first_rss = false;
    if (growth > o_.rss_target_pct) rss_check.met = false;
    const double cpu = ValueAt(p.cpu_ms, t_end) - ValueAt(p.cpu_ms, t0_);
    emit("cpu_pct", cpu / (run_s * 10.0), "% of one core", q);

    // Speed, first and last window, and the noise between windows.
    if (p.kind != Kind::kRecorder) {
      std::vector<double> fps_series, p99_series;
      for (int k = 0; k < windows; ++k) {
        const WindowFigures f = Figures(p, t0_ + k * w, t0_ + (k + 1) * w);
        fps_series.push_back(f.fps);
        p99_series.push_back(f.p99);
      }
      const WindowFigures a = Figures(p, first0, first1), b = Figures(p, last0, last1);
      const std::string at = p.kind == Kind::kSite ? "encoded (site)" : "decoded (viewer)";
      const std::string fps_of = p.kind == Kind::kSite ? "published" : "received";
      for (const auto& [name, f] : {std::pair{"first", a}, std::pair{"last", b}}) {
        emit("fps", f.fps, "1/s", with({{"window", name}, {"frames", fps_of}}));
        emit("latency_p50_ms", f.p50, "ms", with({{"window", name}, {"from", "capture"}, {"to", at}}));
        emit("latency_p99_ms", f.p99, "ms", with({{"window", name}, {"from", "capture"}, {"to", at}}));
        if (p.kind == Kind::kSite) emit("cpu_ms_per_frame", f.cpu_ms_per_frame, "ms", with({{"window", name}}));
      }
      const double fps_noise = SuccessiveNoise(fps_series), lat_noise = SuccessiveNoise(p99_series);
      const double fps_tol = std::max(0.10 * a.fps, 2 * fps_noise), lat_tol = std::max(0.20 * a.p99, 2 * lat_noise);
      const double fps_change = a.fps > 0 ? 100.0 * (b.fps - a.fps) / a.fps : 0;
      const double lat_change = a.p99 > 0 ? 100.0 * (b.p99 - a.p99) / a.p99 : 0;
      emit("fps_change_pct", fps_change, "%",
           with({{"tolerance_pct", num(a.fps > 0 ? 100 * fps_tol / a.fps : 0)}, {"noise_fps", num(fps_noise)}}));
      emit("latency_p99_change_pct", lat_change, "%",
           with({{"tolerance_pct", num(a.p99 > 0 ? 100 * lat_tol / a.p99 : 0)}, {"noise_ms", num(lat_noise)}}));
      if (b.fps < a.fps - fps_tol || a.fps <= 0) fps_check.met = false;
      if (b.p99 > a.p99 + lat_tol) lat_check.met = false;
      if (first_fps || fps_change < fps_check.worst) fps_check.worst = fps_change, fps_check.worst_process = p.name;
      if (first_lat || lat_change > lat_check.worst) lat_check.worst = lat_change, lat_check.worst_process = p.name;
      first_fps = first_lat = false;
    }

    // Errors that the programs count.
    Proc& mp = *up;
    if (p.kind == Kind::kSite) {
      mp.AddError("refused", p.name + ": the session server refused " + std::to_string(p.refused) + " connections",
                  p.refused);
      mp.AddError("violation", p.name + ": " + std::to_string(p.violations) + " protocol violations", p.violations);
      emit("fanout_dropped_frames", static_cast<double>(p.fanout_dropped), "frames",
           with({{"sent", std::to_string(p.fanout_sent)}, {"note", "whole video frames dropped for slow viewers"}}));
    } else if (!p.lines.empty()) {
      const CallLine& end = p.lines.back();
      mp.AddError("reconnect", p.name + ": connected " + std::to_string(end.connects) + " times",
                  end.connects - 1);
      mp.AddError("decode", p.name + ": " + std::to_string(end.decode_errors) + " decode errors", end.decode_errors);
      int64_t down = 0;
      for (const CallLine& c : p.lines)
        if (c.t >= t0_ && c.t <= t_end && c.state != "connected") ++down;
      mp.AddError("disconnected", p.name + ": " + std::to_string(down) + " stats lines while not connected", down);
      if (p.kind == Kind::kParticipant) {
        const CallLine* s = LineAt(p, t0_);
        const CallLine* e = LineAt(p, t_end);
        if (s && e) {
          emit("audio_underruns", static_cast<double>(e->underflows - s->underflows), "pulls",
               with({{"note", "jitter buffer pulls with nothing to play (20 ms each)"}}));
          emit("audio_concealed", static_cast<double>(e->concealed - s->concealed), "frames",
               with({{"late", std::to_string(e->late - s->late)}}));
          const double expected = (e->t - s->t) * 50.0;  // 20 ms frames
          emit("audio_heard_fraction", expected > 0 ? static_cast<double>(e->audio_heard - s->audio_heard) / expected : 0,
               "1", with({{"of", "the other participant's 50 voice frames per second"}}));
          emit("voice_sent_per_s", (e->t > s->t) ? static_cast<double>(e->voice_sent - s->voice_sent) / (e->t - s->t) : 0,
               "1/s", q);
        }
      }
    }
  }

  // The recording.
  {
    const std::string info = dir_ + "/recording-info.json";
    const int rc = std::system(("'" + bin_ + "/holoport-record' --info '" + recording_ + "' --json > '" + info +
                                "' 2> '" + dir_ + "/recording-info.log'")
                                   .c_str());
    std::ifstream f(info);
    const std::string text((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
    const auto j = nlohmann::json::parse(text, nullptr, false);
    Proc* rec = nullptr;
    for (auto& p : procs_)
      if (p->kind == Kind::kRecorder) rec = p.get();
    if (rc != 0 || j.is_discarded() || !j.value("valid", false) || !j.value("clean", false)) {
      if (rec) rec->AddError("recording", "the recording does not validate or was not closed cleanly (see " + dir_ +
                                              "/recording-info.log)");
    } else {
      const double dur_s = j.value("duration_us", int64_t{0}) * 1e-6;
      emit("recording_mb_per_min", j.value("bytes_per_minute", 0.0) / 1e6, "MB/min",
           {{"process", "recorder"}, {"minutes", num(dur_s / 60)}});
      emit("recording_fps", dur_s > 0 ? j.value("mesh_frames", 0.0) / dur_s : 0, "1/s",
           {{"process", "recorder"}, {"audio_pose", std::to_string(j.value("audio_pose", int64_t{0}))}});
    }
  }

  for (auto& up : procs_) {
    for (const auto& [kind, n] : up->errors) {
      total_errors += n;
      emit("errors", static_cast<double>(n), "count",
           {{"process", up->name}, {"kind", kind}, {"example", up->error_example[kind]}});
      spdlog::warn("soak: {}: {} {} error(s), e.g. {}", up->name, n, kind, up->error_example[kind]);
    }
  }
  emit("errors", static_cast<double>(total_errors), "count", {{"process", "all"}});
  err_check.met = total_errors == 0;
  err_check.worst = static_cast<double>(total_errors);
  err_check.worst_process = "all";

  bool pass = true;
  for (const Check* c : {&rss_check, &fps_check, &lat_check, &err_check}) {
    emit("target_met", c->met ? 1 : 0, "bool",
         {{"target", c->target}, {"worst_process", c->worst_process}, {"worst_value", num(c->worst)}});
    pass = pass && c->met;
  }
  emit("soak_pass", pass ? 1 : 0, "bool", {{"minutes", num(run_s / 60)}});
  spdlog::info("soak: {} after {:.1f} min: RSS growth worst {:+.1f} % ({}), fps change worst {:+.1f} % ({}), "
               "latency p99 change worst {:+.1f} % ({}), {} errors; load {:.1f}",
               pass ? "PASS" : "FAIL", run_s / 60, rss_check.worst, rss_check.worst_process, fps_check.worst,
               fps_check.worst_process, lat_check.worst, lat_check.worst_process, total_errors,
               MedianIn(load_, first0, last1));
  if (o_.keep_dir.empty()) {
    std::remove(recording_.c_str());
    if (total_errors == 0) {
      std::error_code ec;
      if (std::filesystem::remove_all(dir_, ec); ec) spdlog::warn("soak: could not remove {}: {}", dir_, ec.message());
    } else {
      spdlog::info("soak: logs kept in {}", dir_);
    }
  }
  return pass ? 0 : 1;
}

BenchFn SetupSoak(CLI::App& app) {
  DropCommonOptions(app, {"--frames", "--repeats"});  // this benchmark does not read them
  auto o = std::make_shared<SoakOptions>();
  app.add_option("--minutes", o->minutes,
                 "length of the measured run (after start-up and warm-up); a progress line per window on stderr")
      ->check(CLI::Range(0.1, 1440.0))
      ->capture_default_str();
  app.add_option("--viewers", o->viewers, "decode-only viewers (holoport-call --watch), alternating between the sites")
      ->check(CLI::Range(0, 16))
      ->capture_default_str();
  app.add_option("--pace", o->pace, "each site's camera rate, fps")->check(CLI::Range(1.0, 30.0))->capture_default_str();
  app.add_option("--prerender", o->prerender, "pod frame sets each site renders first and loops")
      ->check(CLI::Range(2, 600))
      ->capture_default_str();
  app.add_option("--aec", o->aec,
                 "participants spatialize the remote voice and cancel its echo (on) or only buffer it (off)")
      ->transform(CLI::Transformer(std::map<std::string, bool>{{"on", true}, {"off", false}}))
      ->default_str("on");
  app.add_option("--warmup", o->warmup_s, "seconds after every client's first frame before measuring")
      ->check(CLI::Range(0.0, 600.0))
      ->capture_default_str();
  app.add_option("--start-timeout", o->start_timeout_s, "seconds the sites may take to publish their first frame")
      ->check(CLI::Range(10.0, 3600.0))
      ->capture_default_str();
  app.add_option("--rss-target-pct", o->rss_target_pct, "largest RSS growth after the first window that passes")
      ->check(CLI::Range(0.0, 1000.0))
      ->capture_default_str();
  app.add_option("--keep", o->keep_dir, "keep logs, stats and the recording in this directory");
  app.add_option("--site-arg", o->site_args,
                 "an extra holoport-server argument for both sites (repeatable; e.g. --site-arg=--jpeg-quality "
                 "--site-arg=70)");
  return [o](const BenchArgs& args) {
    g_interrupted = false;
    struct sigaction sa {};
    sa.sa_handler = OnSoakSignal;
    sigemptyset(&sa.sa_mask);
    struct sigaction old_int {}, old_term {};
    sigaction(SIGINT, &sa, &old_int);
    sigaction(SIGTERM, &sa, &old_term);
    int code = 0;
    {
      Soak soak(args, *o);
      code = soak.Run();
    }  // every child stopped here
    sigaction(SIGINT, &old_int, nullptr);
    sigaction(SIGTERM, &old_term, nullptr);
    return code;
  };
}

HOLO_REGISTER_BENCH_OPTIONS("soak",
                            "a two-site call (fused content, voice both ways), a recorder and decode-only viewers for "
                            "--minutes: RSS growth, fps and latency first vs last minute, audio underruns, errors",
                            SetupSoak);

}  // namespace
}  // namespace holo::bench
