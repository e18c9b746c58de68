// Child processes for the benchmarks that run whole programs (live, pods,
// broadcast, soak): spawning with output to a log file, stopping, their CPU
// time, the wall clock their stamps use, a free TCP port and the directory
// of holoport-bench (where the other programs are), and reading the JSON
// lines they write.
#pragma once

#include <arpa/inet.h>
#include <netinet/in.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdint>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <nlohmann/json.hpp>

#include "common/clock.h"

namespace holo::bench {

// User + system CPU time of process `pid` so far, ms (from /proc); -1 when
// the process is gone or its stat line cannot be read.
inline double ProcessCpuMsOf(pid_t pid) {
  std::ifstream f("/proc/" + std::to_string(pid) + "/stat");
  std::string line;
  if (!std::getline(f, line)) return -1;
  // Fields after the command name (which may hold spaces) start after ")".
  const size_t close = line.rfind(')');
  if (close == std::string::npos || close + 2 > line.size()) return -1;
  std::istringstream in(line.substr(close + 2));
  std::string field;
  std::vector<std::string> fields;
  while (in >> field) fields.push_back(field);
  // fields[0] is field 3 (state); utime and stime are fields 14 and 15.
  if (fields.size() < 13) return -1;
  return 1e3 * (std::stod(fields[11]) + std::stod(fields[12])) / static_cast<double>(sysconf(_SC_CLK_TCK));
}

// Wall-clock time (system clock), seconds since the Unix epoch: the clock of
// the capture and arrival stamps the programs write (as µs).
inline double WallS() { return static_cast<double>(WallClock::Instance().NowUs()) * 1e-6; }

// A TCP port free on every interface right now (0 if none could be bound).
inline uint16_t FreeTcpPort() {
  const int fd = socket(AF_INET, SOCK_STREAM, 0);
  if (fd < 0) return 0;
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_ANY);
  socklen_t len = sizeof a;
  uint16_t port = 0;
  if (bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0 &&
      getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len) == 0)
    port = ntohs(a.sin_port);
  close(fd);
  return port;
}

// The directory holoport-bench runs from.
inline std::string SelfDir() {
  char buf[4096];
  const ssize_t n = readlink("/proc/self/exe", buf, sizeof buf - 1);
  if (n <= 0) return ".";
  std::string p(buf, static_cast<size_t>(n));
  return p.substr(0, p.rfind('/'));
}

// Starts argv[0] (a path) with stdout and stderr in `log_path`; the pid, or
// -1 when fork failed. `tied`: the child runs in its own process group (a
// Ctrl-C in the terminal reaches only holoport-bench, which stops its children
// in order) and gets SIGTERM if the calling thread dies (PR_SET_PDEATHSIG), so
// nothing is left running after a crash; spawn tied children from the thread
// that lives as long as they should.
inline pid_t SpawnLogged(const std::vector<std::string>& argv, const std::string& log_path, bool tied = false) {
  std::vector<char*> cargv;
  for (const auto& a : argv) cargv.push_back(const_cast<char*>(a.c_str()));
  cargv.push_back(nullptr);
  const pid_t parent = getpid();
  const pid_t pid = fork();
  if (pid == 0) {
    if (tied) {
      setpgid(0, 0);
      prctl(PR_SET_PDEATHSIG, SIGTERM);
      if (getppid() != parent) _exit(127);  // the parent died before prctl
    }
    FILE* log = std::fopen(log_path.c_str(), "w");
    if (log) {
      dup2(fileno(log), 1);
      dup2(fileno(log), 2);
    }
    execv(cargv[0], cargv.data());
    // A forked child: no logger (its mutex may be held by a thread that did not fork).
    std::fprintf(stderr, "exec %s failed\n", cargv[0]);
    _exit(127);
  }
  return pid < 0 ? -1 : pid;
}

// Sends `sig`, then SIGKILL after `grace_s`; reaps the process and returns
// its wait status (-1 for no process).
inline int StopProcess(pid_t pid, int sig = SIGTERM, double grace_s = 10) {
  if (pid <= 0) return -1;
  kill(pid, sig);
  int status = 0;
  const auto until = std::chrono::steady_clock::now() + std::chrono::duration<double>(grace_s);
  while (std::chrono::steady_clock::now() < until) {
    if (waitpid(pid, &status, WNOHANG) == pid) return status;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  kill(pid, SIGKILL);
  waitpid(pid, &status, 0);
  return status;
}

// The JSON objects of a file of JSON lines (a program's figures), skipping
// lines that are not objects (a line cut short by a killed process).
inline std::vector<nlohmann::json> ReadJsonLines(const std::string& path) {
  std::vector<nlohmann::json> out;
  std::ifstream f(path);
  std::string line;
  while (std::getline(f, line)) {
    auto j = nlohmann::json::parse(line, nullptr, /*allow_exceptions=*/false);
    if (!j.is_discarded() && j.is_object()) out.push_back(std::move(j));
  }
  return out;
}

}  // namespace holo::bench
