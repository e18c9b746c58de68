// Personal HRTFs from SOFA files (AES69, SimpleFreeFieldHRIR) through
// libmysofa, and a binaural renderer that uses them: head-related impulse
// responses interpolated between the measured directions (libmysofa's
// inverse-distance weighting of the nearest measurements), resampled to the
// output rate, convolved with each source, with a crossfade between the old
// and the new filter over every block whose direction changed, so a fast head
// turn does not click.
#pragma once

#include <Eigen/Core>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "common/status.h"

struct MYSOFA_HRTF;
struct MYSOFA_EASY;

namespace holo::audio {

// Largest SOFA file read, and largest filter accepted (taps at the file rate):
// a hostile file cannot exhaust memory or make rendering unaffordable.
inline constexpr uint64_t kMaxSofaFileBytes = 256ull << 20;
inline constexpr int kMaxSofaTaps = 8192;

// Checks that a parsed SOFA file has the layout the renderer needs: the
// SimpleFreeFieldHRIR convention, FIR data, 2 receivers (ears), ≥ 1
// measurement, 1..kMaxSofaTaps taps, Data.IR of M × R × N finite values, a
// positive sample rate in 8000..384000 Hz, M source positions. Returns
// InvalidArgument naming the first rule broken ("SOFA layout: 1 receiver,
// need 2 (left and right ear)").
Status CheckSofaLayout(const MYSOFA_HRTF& hrtf);

class SofaHrtf {
 public:
  // Reads `path` (untrusted), checks its layout, resamples the filters to
  // `sample_rate` and prepares the direction lookup. NotFound if the file is
  // missing; InvalidArgument with the reason if it is not a SOFA file libmysofa
  // can read or breaks a rule of CheckSofaLayout.
  static StatusOr<std::unique_ptr<SofaHrtf>> Open(const std::string& path, int sample_rate);
  // Same for a file held in memory (`path` only names it in errors). The
  // bytes are parsed first in a forked child, so a malformed file that
  // crashes libmysofa's HDF5 reader is refused instead of crashing us.
  static StatusOr<std::unique_ptr<SofaHrtf>> OpenBytes(const std::string& bytes, int sample_rate,
                                                       const std::string& path = "SOFA data");
  ~SofaHrtf();
  SofaHrtf(const SofaHrtf&) = delete;
  SofaHrtf& operator=(const SofaHrtf&) = delete;

  int filter_length() const { return filter_length_; }  // taps at the output rate, incl. the file's delays
  int sample_rate() const { return sample_rate_; }
  int measurements() const { return measurements_; }
  const std::string& description() const { return description_; }
  // The HRIR pair for a source in direction `dir` (head frame: x ahead, y left,
  // z up; any length > 0), interpolated between the nearest measurements;
  // each of `left`, `right` gets filter_length() taps.
  void Filter(const Eigen::Vector3f& dir, std::vector<float>* left, std::vector<float>* right) const;

 private:
  SofaHrtf() = default;
  MYSOFA_EASY* easy_ = nullptr;
  int filter_length_ = 0, raw_length_ = 0, sample_rate_ = 0, measurements_ = 0;
  std::string description_;
};

// Interaural cues computed directly from the file's own impulse responses at
// the file's rate (no resampling, no interpolation): the measurement nearest
// to (`azimuth_deg`, + right, elevation 0). ITD: lag of the left ear's IR
// behind the right's at the peak of their cross-correlation within ±1 ms
// (parabolic sub-sample peak); ILD: right − left energy, dB.
struct SofaCues {
  double itd_ms = 0, ild_db = 0;
  double azimuth_deg = 0, elevation_deg = 0;  // of the measurement used, + right
};
StatusOr<SofaCues> SofaFileCues(const std::string& path, double azimuth_deg);

// Convolves one mono source with an HRIR pair; when the filter changes the
// block is rendered with both and crossfaded (raised cosine over the block).
class HrtfConvolver {
 public:
  explicit HrtfConvolver(const SofaHrtf& hrtf) : hrtf_(hrtf) {}
  // Renders `mono` from direction `dir` (head frame) at gain `gain`, adding
  // interleaved stereo into `stereo_out` (2 × mono.size() values).
  // `crossfade` false switches filters at the block start (for comparisons).
  void Process(std::span<const float> mono, const Eigen::Vector3f& dir, float gain, std::span<float> stereo_out,
               bool crossfade = true);

 private:
  void Convolve(const std::vector<float>& h, int ear, std::span<const float> x, std::vector<float>* y) const;
  const SofaHrtf& hrtf_;
  bool have_filter_ = false;
  Eigen::Vector3f dir_ = Eigen::Vector3f::UnitX();
  float gain_ = 1.0f;
  std::vector<float> left_, right_, new_left_, new_right_;
  std::vector<float> history_;  // last filter_length − 1 input samples
  std::vector<float> buf_, y0_, y1_;
};

// libFuzzer-style entry point: arbitrary bytes as a SOFA file. Returns 1 if
// accepted (then the filters it yields are checked), 0 if refused; never crashes.
int FuzzSofa(const uint8_t* data, size_t size);

}  // namespace holo::audio
