// A speech-like test voice whose onsets are placed by the caller: a site
// without a microphone gives its synthetic person this voice, with a
// syllable starting at each moment the person's foot lands and a knock each
// time the ball touches the floor (server/voice/site_voice.h), so voice and
// picture can be checked against each other by eye and ear, and by onset
// detection in tests.
//
// A syllable is a source-filter vowel: a glottal pulse train (F0 110–190 Hz,
// falling 15 % over the syllable) through two formant resonators (one of five
// vowels), after a 12 ms plosive noise burst; 140–260 ms long, attack 4 ms,
// release 40 ms. A knock is a 60 ms decaying 180 Hz tone with a noise click.
// Each event's parameters come from a seeded generator, so the same events
// give the same samples. Peak level ≤ 0.5.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

namespace holo::audio {

class SyntheticVoice {
 public:
  enum class Sound { kSyllable, kKnock };

  explicit SyntheticVoice(uint64_t seed = 1, int sample_rate = 48000);

  // Starts `sound` at sample `offset` of the next Render() call (0 ≤ offset;
  // an offset past that call's length carries over to later calls). A new
  // sound of the same kind replaces one still sounding.
  void Start(Sound sound, int64_t offset);
  // Writes the next `out.size()` samples (mono, [-1, 1]).
  void Render(std::span<float> out);
  // Samples rendered so far.
  int64_t position() const { return position_; }

 private:
  struct Syllable {
    bool active = false;
    int64_t start = 0;  // absolute sample index
    int64_t length = 0;
    double f0 = 150, f1 = 700, f2 = 1200;
    double phase = 0;
    double gain[2] = {0, 0}, a1[2] = {0, 0}, a2[2] = {0, 0};  // resonator coefficients
    double y1[2] = {0, 0}, y2[2] = {0, 0};                    // resonator states
  };
  struct Knock {
    bool active = false;
    int64_t start = 0;
  };
  double Noise();
  float SyllableSample(Syllable& s, int64_t n);
  float KnockSample(const Knock& k, int64_t n);

  int rate_;
  uint64_t rng_;
  int64_t position_ = 0;
  std::vector<std::pair<int64_t, Sound>> pending_;  // absolute start, sound
  Syllable syllable_;
  Knock knock_;
};

}  // namespace holo::audio
