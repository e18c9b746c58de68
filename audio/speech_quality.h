// Objective speech quality of a codec round trip against the original:
// waveform segmental SNR and frequency-weighted segmental SNR (fwSNRseg,
// after Hu & Loizou, "Evaluation of objective quality measures for speech
// enhancement", IEEE TASLP 2008, whose study found it tracks intelligibility
// and quality far better than waveform SNR). Used by tests and the audio bench.
#pragma once

#include <span>

namespace holo::audio {

// The lag in 0..`max_lag` samples by which `out` trails `ref` (maximum
// cross-correlation). Codecs delay their output (Opus: 6.5 ms).
int BestLag(std::span<const float> ref, std::span<const float> out, int max_lag);

// Mean over 20 ms segments with speech (ref segment energy within 40 dB of
// the loudest segment) of 10·log10(|ref|² / |ref − out|²), each clipped to
// [−10, 35] dB; `out` compared at ref[i] ↔ out[i + lag]. A waveform measure:
// it punishes any phase change, so perceptual codecs score low on it.
double SegmentalSnrDb(std::span<const float> ref, std::span<const float> out, int lag);

// fwSNRseg: 30 ms Hann windows, 75% overlap; magnitude spectra in 25 bands
// equally spaced on the Bark scale from 50 Hz to min(8 kHz, Nyquist), each
// frame's band energies normalised to unit sum (so overall gain does not
// count); per band SNR = 10·log10(X² / (X − Y)²) clipped to [−10, 35] dB
// (X, Y band magnitudes of ref and out), weighted by X^0.2; averaged over
// frames with speech (as above).
double FwSegSnrDb(std::span<const float> ref, std::span<const float> out, int lag, int sample_rate);

}  // namespace holo::audio
