#include <algorithm>
#include <cmath>
#include <cstdio>
#include <ctime>

#include <nlohmann/json.hpp>

#include "bench.h"

namespace holo::bench {

std::map<std::string, BenchInfo>& Registry() {
  static std::map<std::string, BenchInfo> registry;
  return registry;
}

bool Register(const std::string& name, const std::string& description, BenchFn fn) {
  return RegisterWithOptions(name, description, NoOptions(std::move(fn)));
}

bool RegisterWithOptions(const std::string& name, const std::string& description, BenchSetup setup) {
  Registry()[name] = BenchInfo{description, std::move(setup)};
  return true;
}

BenchSetup NoOptions(BenchFn fn) {
  return [fn = std::move(fn)](CLI::App&) { return fn; };
}

void EmitFigure(const std::string& bench, const std::string& workload, const std::string& metric, double value,
                const std::string& unit, const std::map<std::string, std::string>& qualifiers) {
  nlohmann::ordered_json j;
  j["bench"] = bench;
  j["workload"] = workload;
  j["metric"] = metric;
  j["value"] = std::isfinite(value) ? std::round(value * 1e4) / 1e4 : 0.0;
  j["unit"] = unit;
  for (const auto& [k, v] : qualifiers) j[k] = v;
  std::printf("%s\n", j.dump().c_str());
  std::fflush(stdout);
}

double ProcessCpuMs() {
  timespec ts{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return 1e3 * static_cast<double>(ts.tv_sec) + 1e-6 * static_cast<double>(ts.tv_nsec);
}

double Mean(const std::vector<double>& values) {
  double sum = 0;
  for (double v : values) sum += v;
  return values.empty() ? 0.0 : sum / static_cast<double>(values.size());
}

std::string Fixed(double v, int digits) {
  char b[64];
  std::snprintf(b, sizeof b, "%.*f", digits, v);
  return b;
}

double Median(std::vector<double> values) {
  if (values.empty()) return 0;
  std::sort(values.begin(), values.end());
  const size_t n = values.size();
  return n % 2 ? values[n / 2] : 0.5 * (values[n / 2 - 1] + values[n / 2]);
}

}  // namespace holo::bench
