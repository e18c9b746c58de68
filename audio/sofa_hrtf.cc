#include "audio/sofa_hrtf.h"

#include <mysofa.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <iterator>
#include <numbers>
#include <thread>

#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

namespace holo::audio {
namespace {

std::string MysofaError(int err) {
  switch (err) {
    case MYSOFA_INVALID_FORMAT: return "not a SOFA (netCDF-4/HDF5) file libmysofa can read";
    case MYSOFA_UNSUPPORTED_FORMAT: return "unsupported HDF5 feature";
    case MYSOFA_NO_MEMORY: return "out of memory";
    case MYSOFA_READ_ERROR: return "read error (truncated?)";
    case MYSOFA_INVALID_ATTRIBUTES: return "invalid or missing SOFA attributes (Conventions, DataType, ...)";
    case MYSOFA_INVALID_DIMENSIONS: return "invalid dimensions (need I=1, C=3, R=2, E=1)";
    case MYSOFA_INVALID_DIMENSION_LIST: return "invalid dimension list of a variable";
    case MYSOFA_INVALID_COORDINATE_TYPE: return "invalid coordinate type";
    case MYSOFA_ONLY_EMITTER_WITH_ECI_SUPPORTED: return "only emitters of size E×C×I supported";
    case MYSOFA_ONLY_DELAYS_WITH_IR_OR_MR_SUPPORTED: return "Data.Delay must be I×R or M×R";
    case MYSOFA_ONLY_THE_SAME_SAMPLING_RATE_SUPPORTED: return "one sampling rate for all measurements needed";
    case MYSOFA_RECEIVERS_WITH_RCI_SUPPORTED: return "ReceiverPosition must be R×C×I";
    case MYSOFA_RECEIVERS_WITH_CARTESIAN_SUPPORTED: return "ReceiverPosition must be cartesian";
    case MYSOFA_INVALID_RECEIVER_POSITIONS: return "receivers must be on the left and right of the listener";
    case MYSOFA_ONLY_SOURCES_WITH_MC_SUPPORTED: return "SourcePosition must be M×C";
    default: return "libmysofa error " + std::to_string(err);
  }
}

std::string Attribute(MYSOFA_ATTRIBUTE* a, const char* name) {
  for (; a != nullptr; a = a->next) {
    if (a->name != nullptr && std::strcmp(a->name, name) == 0) return a->value != nullptr ? a->value : "";
  }
  return "";
}

StatusOr<std::string> ReadBytes(const std::string& path) {
  std::ifstream f(path, std::ios::binary | std::ios::ate);
  if (!f) return NotFound(path + ": cannot open");
  const std::streamoff size = f.tellg();
  if (size < 0) return InvalidArgument(path + ": cannot read its size");
  if (static_cast<uint64_t>(size) > kMaxSofaFileBytes) {
    return InvalidArgument(path + ": " + std::to_string(size) + " bytes, more than the " +
                           std::to_string(kMaxSofaFileBytes) + " accepted for a SOFA file");
  }
  std::string bytes(static_cast<size_t>(size), '\0');
  f.seekg(0);
  if (!f.read(bytes.data(), size)) return InvalidArgument(path + ": read failed");
  return bytes;
}

struct HrtfDeleter {
  void operator()(MYSOFA_HRTF* h) const { mysofa_free(h); }
};
using HrtfPtr = std::unique_ptr<MYSOFA_HRTF, HrtfDeleter>;

// libmysofa's HDF5 reader can crash on malformed files (a truncated file
// smashed its stack in our tests). The bytes are therefore first parsed in a
// forked child; only if it survives are they parsed here. Called at start-up
// (before audio threads run), so fork's limits on multi-threaded processes do
// not bite. Returns OK if the child parsed without crashing.
Status ProbeInChild(const std::string& path, const std::string& bytes) {
  const pid_t pid = fork();
  if (pid < 0) return Internal(path + ": fork failed for the SOFA parse probe");
  if (pid == 0) {
    // The probe's own crash reports (glibc's "stack smashing detected", a
    // sanitizer's) would reach the user's terminal as if the program had
    // crashed; the parent reports the malformed file instead. glibc writes
    // its fatal messages to the terminal unless told to use stderr.
    setenv("LIBC_FATAL_STDERR_", "1", 1);
    const int devnull = open("/dev/null", O_WRONLY);
    if (devnull >= 0) dup2(devnull, STDERR_FILENO);
    int err = 0;
    MYSOFA_HRTF* h = mysofa_load_data(bytes.data(), bytes.size(), &err);
    if (h != nullptr) {
      const bool ok = err == MYSOFA_OK && CheckSofaLayout(*h).ok() && mysofa_check(h) == MYSOFA_OK;
      mysofa_free(h);
      (void)ok;  // the parent parses again for the message; resampling a checked set is plain arithmetic
    }
    _exit(0);
  }
  int status = 0;
  // A hostile file must not hang the caller either: 20 s, then the probe is killed.
  for (int waited_ms = 0;; waited_ms += 10) {
    const pid_t r = waitpid(pid, &status, WNOHANG);
    if (r == pid) break;
    if (r < 0) return Internal(path + ": waitpid failed for the SOFA parse probe");
    if (waited_ms >= 20000) {
      kill(pid, SIGKILL);
      waitpid(pid, &status, 0);
      return InvalidArgument(path + ": the SOFA parser did not finish within 20 s (malformed file)");
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  if (WIFSIGNALED(status)) {
    return InvalidArgument(path + ": malformed SOFA/HDF5 file (the parser crashed on it, signal " +
                           std::to_string(WTERMSIG(status)) + ")");
  }
  // A sanitizer reports a memory error by exiting non-zero instead of a signal.
  if (!WIFEXITED(status) || WEXITSTATUS(status) != 0) {
    return InvalidArgument(path + ": malformed SOFA/HDF5 file (the parser failed on it, exit status " +
                           std::to_string(WIFEXITED(status) ? WEXITSTATUS(status) : -1) + ")");
  }
  return OkStatus();
}

StatusOr<HrtfPtr> LoadChecked(const std::string& path, const std::string& bytes) {
  HOLO_RETURN_IF_ERROR(ProbeInChild(path, bytes));
  int err = 0;
  HrtfPtr h(mysofa_load_data(bytes.data(), bytes.size(), &err));
  if (h == nullptr || err != MYSOFA_OK) return InvalidArgument(path + ": " + MysofaError(err));
  if (Status s = CheckSofaLayout(*h); !s.ok()) return InvalidArgument(path + ": " + s.message());
  err = mysofa_check(h.get());
  if (err != MYSOFA_OK) return InvalidArgument(path + ": SOFA layout: " + MysofaError(err));
  return h;
}

}  // namespace

Status CheckSofaLayout(const MYSOFA_HRTF& h) {
  const std::string conv = Attribute(h.attributes, "SOFAConventions");
  if (conv != "SimpleFreeFieldHRIR") {
    return InvalidArgument("SOFA layout: convention '" + conv + "', need SimpleFreeFieldHRIR");
  }
  const std::string type = Attribute(h.attributes, "DataType");
  if (type != "FIR") return InvalidArgument("SOFA layout: DataType '" + type + "', need FIR");
  if (h.R != 2) {
    return InvalidArgument("SOFA layout: " + std::to_string(h.R) + " receiver(s), need 2 (left and right ear)");
  }
  if (h.E != 1) return InvalidArgument("SOFA layout: " + std::to_string(h.E) + " emitters, need 1");
  if (h.M < 1) return InvalidArgument("SOFA layout: no measurements");
  if (h.N < 1 || h.N > static_cast<unsigned>(kMaxSofaTaps)) {
    return InvalidArgument("SOFA layout: " + std::to_string(h.N) + " taps per filter, need 1.." +
                           std::to_string(kMaxSofaTaps));
  }
  const uint64_t want = static_cast<uint64_t>(h.M) * h.R * h.N;
  if (h.DataIR.values == nullptr || h.DataIR.elements != want) {
    return InvalidArgument("SOFA layout: Data.IR has " + std::to_string(h.DataIR.elements) + " values, M×R×N = " +
                           std::to_string(want));
  }
  for (unsigned i = 0; i < h.DataIR.elements; ++i) {
    if (!std::isfinite(h.DataIR.values[i])) {
      return InvalidArgument("SOFA layout: Data.IR value " + std::to_string(i) + " is not finite");
    }
  }
  if (h.DataSamplingRate.values == nullptr || h.DataSamplingRate.elements != 1) {
    return InvalidArgument("SOFA layout: Data.SamplingRate must be one value");
  }
  const float rate = h.DataSamplingRate.values[0];
  if (!(rate >= 8000.0f && rate <= 384000.0f)) {
    return InvalidArgument("SOFA layout: Data.SamplingRate " + std::to_string(rate) + " outside 8000..384000 Hz");
  }
  if (h.SourcePosition.values == nullptr || h.SourcePosition.elements != h.M * h.C || h.C != 3) {
    return InvalidArgument("SOFA layout: SourcePosition has " + std::to_string(h.SourcePosition.elements) +
                           " values, need M×3 = " + std::to_string(h.M * 3));
  }
  for (unsigned i = 0; i < h.SourcePosition.elements; ++i) {
    if (!std::isfinite(h.SourcePosition.values[i])) return InvalidArgument("SOFA layout: SourcePosition not finite");
  }
  if (h.DataDelay.values != nullptr) {
    if (h.DataDelay.elements != h.R && h.DataDelay.elements != h.M * h.R) {
      return InvalidArgument("SOFA layout: Data.Delay has " + std::to_string(h.DataDelay.elements) +
                             " values, need R or M×R");
    }
    for (unsigned i = 0; i < h.DataDelay.elements; ++i) {
      const float d = h.DataDelay.values[i];
      // Data.Delay is in samples in SOFA 1.0; more than 0.1 s is no head.
      if (!(d >= 0.0f && d <= 0.1f * rate)) {
        return InvalidArgument("SOFA layout: Data.Delay " + std::to_string(d) + " samples is not a head's delay");
      }
    }
  }
  return OkStatus();
}

SofaHrtf::~SofaHrtf() {
  if (easy_ != nullptr) mysofa_close(easy_);
}

StatusOr<std::unique_ptr<SofaHrtf>> SofaHrtf::Open(const std::string& path, int sample_rate) {
  HOLO_ASSIGN_OR_RETURN(const std::string bytes, ReadBytes(path));
  return OpenBytes(bytes, sample_rate, path);
}

StatusOr<std::unique_ptr<SofaHrtf>> SofaHrtf::OpenBytes(const std::string& bytes, int sample_rate,
                                                        const std::string& path) {
  if (sample_rate < 8000 || sample_rate > 192000) {
    return InvalidArgument("SOFA output rate must be in 8000..192000, got " + std::to_string(sample_rate));
  }
  if (bytes.size() > kMaxSofaFileBytes) return InvalidArgument(path + ": file too large");
  HOLO_ASSIGN_OR_RETURN(HrtfPtr checked, LoadChecked(path, bytes));
  float max_delay = 0;
  if (checked->DataDelay.values != nullptr) {
    for (unsigned i = 0; i < checked->DataDelay.elements; ++i) max_delay = std::max(max_delay, checked->DataDelay.values[i]);
  }
  const float file_rate = checked->DataSamplingRate.values[0];
  std::unique_ptr<SofaHrtf> s(new SofaHrtf());
  s->measurements_ = static_cast<int>(checked->M);
  s->description_ = Attribute(checked->attributes, "Title");
  if (s->description_.empty()) s->description_ = Attribute(checked->attributes, "DatabaseName");
  int err = 0, len = 0;
  // Normalised so a source straight ahead has unit loudness (same level as the default path).
  s->easy_ = mysofa_open_data(bytes.data(), static_cast<long>(bytes.size()), static_cast<float>(sample_rate), &len, &err);
  if (s->easy_ == nullptr || err != MYSOFA_OK) return InvalidArgument(path + ": " + MysofaError(err));
  if (len < 1 || len > 4 * kMaxSofaTaps) return InvalidArgument(path + ": filter length " + std::to_string(len));
  s->raw_length_ = len;
  s->sample_rate_ = sample_rate;
  s->filter_length_ = len + static_cast<int>(std::ceil(max_delay * sample_rate / file_rate));
  return s;
}

void SofaHrtf::Filter(const Eigen::Vector3f& dir, std::vector<float>* left, std::vector<float>* right) const {
  const Eigen::Vector3f d = dir.norm() > 1e-6f ? dir.normalized() : Eigen::Vector3f::UnitX();
  std::vector<float> l(static_cast<size_t>(raw_length_)), r(static_cast<size_t>(raw_length_));
  float dl = 0, dr = 0;  // seconds
  mysofa_getfilter_float(easy_, d.x(), d.y(), d.z(), l.data(), r.data(), &dl, &dr);
  left->assign(static_cast<size_t>(filter_length_), 0.0f);
  right->assign(static_cast<size_t>(filter_length_), 0.0f);
  const int sl = std::clamp(static_cast<int>(std::lround(dl * sample_rate_)), 0, filter_length_ - raw_length_);
  const int sr = std::clamp(static_cast<int>(std::lround(dr * sample_rate_)), 0, filter_length_ - raw_length_);
  std::copy(l.begin(), l.end(), left->begin() + sl);
  std::copy(r.begin(), r.end(), right->begin() + sr);
}

StatusOr<SofaCues> SofaFileCues(const std::string& path, double azimuth_deg) {
  HOLO_ASSIGN_OR_RETURN(const std::string bytes, ReadBytes(path));
  HOLO_ASSIGN_OR_RETURN(HrtfPtr h, LoadChecked(path, bytes));
  mysofa_tocartesian(h.get());
  const double a = -azimuth_deg * std::numbers::pi / 180.0;  // SOFA azimuth turns left
  const Eigen::Vector3d want(std::cos(a), std::sin(a), 0.0);
  unsigned best = 0;
  double best_dot = -2;
  for (unsigned m = 0; m < h->M; ++m) {
    Eigen::Vector3d p(h->SourcePosition.values[3 * m], h->SourcePosition.values[3 * m + 1],
                      h->SourcePosition.values[3 * m + 2]);
    if (p.norm() < 1e-9) continue;
    const double dot = p.normalized().dot(want);
    if (dot > best_dot) {
      best_dot = dot;
      best = m;
    }
  }
  // Receiver 0 is the left ear unless the file puts it on the right (y < 0).
  bool swap = false;
  if (h->ReceiverPosition.values != nullptr && h->ReceiverPosition.elements >= 6) {
    swap = h->ReceiverPosition.values[1] < h->ReceiverPosition.values[4];
  }
  const unsigned n = h->N;
  const float* l = h->DataIR.values + (static_cast<size_t>(best) * 2 + (swap ? 1 : 0)) * n;
  const float* r = h->DataIR.values + (static_cast<size_t>(best) * 2 + (swap ? 0 : 1)) * n;
  const double rate = h->DataSamplingRate.values[0];
  double el = 0, er = 0;
  for (unsigned i = 0; i < n; ++i) {
    el += static_cast<double>(l[i]) * l[i];
    er += static_cast<double>(r[i]) * r[i];
  }
  // Cross-correlation c(k) = Σ r[i] l[i + k]: k > 0 when the left ear hears it later.
  const int max_lag = static_cast<int>(std::ceil(0.001 * rate));
  std::vector<double> c(static_cast<size_t>(2 * max_lag + 1), 0.0);
  for (int k = -max_lag; k <= max_lag; ++k) {
    double s = 0;
    for (int i = 0; i < static_cast<int>(n); ++i) {
      const int j = i + k;
      if (j >= 0 && j < static_cast<int>(n)) s += static_cast<double>(r[i]) * l[j];
    }
    c[static_cast<size_t>(k + max_lag)] = s;
  }
  const size_t bi = static_cast<size_t>(std::max_element(c.begin(), c.end()) - c.begin());
  double lag = static_cast<double>(bi) - max_lag;
  if (bi > 0 && bi + 1 < c.size()) {
    const double y0 = c[bi - 1], y1 = c[bi], y2 = c[bi + 1];
    const double den = y0 - 2 * y1 + y2;
    if (std::abs(den) > 1e-30) lag += 0.5 * (y0 - y2) / den;
  }
  SofaCues cues;
  cues.itd_ms = lag * 1000.0 / rate;
  cues.ild_db = 10.0 * std::log10((er + 1e-30) / (el + 1e-30));
  const Eigen::Vector3d p(h->SourcePosition.values[3 * best], h->SourcePosition.values[3 * best + 1],
                          h->SourcePosition.values[3 * best + 2]);
  cues.azimuth_deg = -std::atan2(p.y(), p.x()) * 180.0 / std::numbers::pi;
  cues.elevation_deg = std::atan2(p.z(), std::hypot(p.x(), p.y())) * 180.0 / std::numbers::pi;
  return cues;
}

void HrtfConvolver::Convolve(const std::vector<float>& h, int ear, std::span<const float> x,
                             std::vector<float>* y) const {
  (void)ear;
  const size_t L = h.size(), n = x.size();
  y->assign(n, 0.0f);
  // buf_ = history (L − 1) ++ x; y[i] = Σ_k h[k] · buf_[i + L − 1 − k].
  for (size_t i = 0; i < n; ++i) {
    const float* b = buf_.data() + i + L - 1;
    float s = 0;
    for (size_t k = 0; k < L; ++k) s += h[k] * *(b - k);
    (*y)[i] = s;
  }
}

void HrtfConvolver::Process(std::span<const float> mono, const Eigen::Vector3f& dir, float gain,
                            std::span<float> stereo_out, bool crossfade) {
  const size_t L = static_cast<size_t>(hrtf_.filter_length());
  const size_t n = mono.size();
  if (history_.size() != L - 1) history_.assign(L - 1, 0.0f);
  buf_.assign(history_.begin(), history_.end());
  buf_.insert(buf_.end(), mono.begin(), mono.end());
  const bool moved = !have_filter_ || std::acos(std::clamp(dir.normalized().dot(dir_), -1.0f, 1.0f)) > 1e-3f;
  const bool regain = std::abs(gain - gain_) > 1e-6f;
  if (!have_filter_) {
    hrtf_.Filter(dir, &left_, &right_);
    dir_ = dir.normalized();
    gain_ = gain;
    have_filter_ = true;
  }
  std::vector<float> yl, yr;
  Convolve(left_, 0, mono, &yl);
  Convolve(right_, 1, mono, &yr);
  if (moved || regain) {
    if (moved) hrtf_.Filter(dir, &new_left_, &new_right_);
    const std::vector<float>& nl = moved ? new_left_ : left_;
    const std::vector<float>& nr = moved ? new_right_ : right_;
    std::vector<float> zl, zr;
    Convolve(nl, 0, mono, &zl);
    Convolve(nr, 1, mono, &zr);
    for (size_t i = 0; i < n; ++i) {
      const float w = crossfade ? 0.5f - 0.5f * std::cos(std::numbers::pi_v<float> * (static_cast<float>(i) + 0.5f) /
                                                         static_cast<float>(n))
                                : 1.0f;
      yl[i] = (1 - w) * gain_ * yl[i] + w * gain * zl[i];
      yr[i] = (1 - w) * gain_ * yr[i] + w * gain * zr[i];
    }
    if (moved) {
      left_.swap(new_left_);
      right_.swap(new_right_);
      dir_ = dir.normalized();
    }
    gain_ = gain;
  } else {
    for (size_t i = 0; i < n; ++i) {
      yl[i] *= gain_;
      yr[i] *= gain_;
    }
  }
  for (size_t i = 0; i < n && 2 * i + 1 < stereo_out.size(); ++i) {
    stereo_out[2 * i] += yl[i];
    stereo_out[2 * i + 1] += yr[i];
  }
  history_.assign(buf_.end() - static_cast<std::ptrdiff_t>(L - 1), buf_.end());
}

int FuzzSofa(const uint8_t* data, size_t size) {
  auto h = SofaHrtf::OpenBytes(std::string(reinterpret_cast<const char*>(data), size), 48000, "fuzz input");
  if (!h.ok()) return 0;
  std::vector<float> l, r;
  (*h)->Filter({0.3f, -0.9f, 0.1f}, &l, &r);
  HOLO_CHECK(static_cast<int>(l.size()) == (*h)->filter_length() && l.size() == r.size());
  return 1;
}

}  // namespace holo::audio
