// holoport-client as a program, for the tests that run it: where it is built
// and running a command line to its end.
#pragma once

#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <string>

#include "common/status.h"

namespace holo::test {

// build/bin/holoport-client (the tests live in build/tests/).
inline std::string ClientPath() {
  std::array<char, 4096> buf{};
  const ssize_t n = readlink("/proc/self/exe", buf.data(), buf.size() - 1);
  HOLO_CHECK(n > 0);
  return (std::filesystem::path(std::string(buf.data(), n)).parent_path().parent_path() / "bin" / "holoport-client")
      .string();
}

struct RunResult {
  int exit_code = -1;
  bool signaled = false;
  std::string output;  // stdout and stderr
};

// Runs `command` through the shell (stderr into stdout) and waits for it;
// `on_started`, when set, is called once the child exists, before its output
// is read.
inline RunResult RunCommand(const std::string& command, const std::function<void()>& on_started = {}) {
  RunResult r;
  FILE* p = popen((command + " 2>&1").c_str(), "r");
  HOLO_CHECK(p != nullptr);
  if (on_started) on_started();
  std::array<char, 4096> buf;
  size_t n;
  while ((n = fread(buf.data(), 1, buf.size(), p)) > 0) r.output.append(buf.data(), n);
  const int status = pclose(p);
  r.signaled = WIFSIGNALED(status);
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

}  // namespace holo::test
