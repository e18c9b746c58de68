// V1 video colour (PROTOCOL.md §8, colour codec 4) in the browser: the blob
// parser and the mask decoders are a port of protocol/video_codec.cc (the
// masks bit-identical, checked against the C++ decoder's golden files); the
// picture is decoded by the browser's own H.264 decoder through WebCodecs
// (VideoColorStream, one per pod). Safe on untrusted input: malformed data
// throws a DecodeError naming the field.

import { Reader, DecodeError, fail } from './bytes.js';
import { LIMITS, unzstdRows, getVarint } from './color.js';

const FLAG_KEY = 1, FLAG_444 = 2, FLAG_MASK_BLOCKS = 4, FLAG_WINDOW = 8;

// The header and the two byte ranges of a V1 blob (views into `blob`).
export function parseVideoBlob(blob, limits = LIMITS) {
  const r = new Reader(blob);
  const codec = r.u8('v1.codec');
  if (codec !== 4) fail(`v1.codec: ${codec} is not the video codec (4)`);
  const flags = r.u8('v1.flags');
  if (flags & ~(FLAG_KEY | FLAG_444 | FLAG_MASK_BLOCKS | FLAG_WINDOW)) fail(`v1.flags: unknown bits in ${flags}`);
  const width = r.u16('v1.width'), height = r.u16('v1.height');
  if (!width || !height || width & 1 || height & 1 || width > limits.maxImageDim || height > limits.maxImageDim ||
      width * height > limits.maxImagePixels) {
    fail(`v1.size: ${width}x${height} is not even or exceeds the limits`);
  }
  const library = r.u8('v1.library');
  if (library < 1 || library > 3) fail(`v1.library: unknown video library ${library}`);
  if (library === 3) fail('v1.library: 3 (AV1) is reserved, not implemented');
  const frameNumber = r.u32('v1.frame_number');
  // The picture's window in the image (the whole image without flag bit 3).
  let window = { x: 0, y: 0, w: width, h: height };
  if (flags & FLAG_WINDOW) {
    const x = r.u16('v1.window_x'), y = r.u16('v1.window_y'), w = r.u16('v1.window_width'), h = r.u16('v1.window_height');
    if (!w || !h || w & 1 || h & 1 || x + w > width || y + h > height) {
      fail(`v1.window: ${w}x${h} at ${x},${y} is not even-sized or leaves the ${width}x${height} image`);
    }
    window = { x, y, w, h };
  }
  const mask = r.blob32('v1.mask');
  const video = r.blob32('v1.video');
  r.expectEnd('v1 blob');
  if (!video.length) fail('v1.video: empty picture');
  return {
    flags, width, height, library, frameNumber, window, mask, video,
    keyframe: (flags & FLAG_KEY) !== 0, chroma444: (flags & FLAG_444) !== 0, maskBlocks: (flags & FLAG_MASK_BLOCKS) !== 0,
  };
}

// ------------------------------------------------------------ mask blocks
// PROTOCOL.md §8 "Coded mask blocks": block types, then the mixed blocks'
// pixels, through an adaptive binary range decoder.

class BitDecoder {
  constructor(bytes) {
    this.bytes = bytes;
    this.pos = 0;
    this.pastEnd = 0;
    this.range = 0xffffffff;
    this.code = 0;
    for (let i = 0; i < 5; ++i) this.code = ((this.code << 8) | this.next()) >>> 0;
  }
  next() {
    if (this.pos < this.bytes.length) return this.bytes[this.pos++];
    this.pastEnd++;
    return 0;
  }
  // probs[i]: the probability of a 0, in 1/4096.
  get(probs, i) {
    const p = probs[i];
    const bound = (this.range >>> 12) * p;  // < 2^32: exact in a double
    let bit;
    if (this.code < bound) {
      this.range = bound;
      probs[i] = p + ((4096 - p) >> 4);
      bit = 0;
    } else {
      this.code -= bound;
      this.range -= bound;
      probs[i] = p - (p >> 4);
      bit = 1;
    }
    while (this.range < 0x1000000) {
      this.range = (this.range * 256) >>> 0;
      this.code = ((this.code << 8) | this.next()) >>> 0;
    }
    return bit;
  }
}

function decodeMaskBlocks(data, w, h) {
  const B = 16, bw = Math.ceil(w / B), bh = Math.ceil(h / B);
  if (!data.length || data[0] !== 0) fail('v1.mask: coded blocks do not start with a zero byte');
  const dec = new BitDecoder(data);
  const types = new Uint8Array(bw * bh);
  const mixed = new Uint16Array(9).fill(2048), full = new Uint16Array(4).fill(2048);
  for (let by = 0; by < bh; ++by) {
    for (let bx = 0; bx < bw; ++bx) {
      const left = bx > 0 ? types[by * bw + bx - 1] : 0, upper = by > 0 ? types[(by - 1) * bw + bx] : 0;
      if (dec.get(mixed, left * 3 + upper)) types[by * bw + bx] = 2;
      else types[by * bw + bx] = dec.get(full, (left === 1 ? 1 : 0) + (upper === 1 ? 2 : 0));
    }
  }
  // Row by row, blocks left to right: a full block's pixels are set before
  // the mixed block to its right reads them as context.
  const mask = new Uint8Array(w * h);
  const probs = new Uint16Array(64).fill(2048);
  const zeros = new Uint8Array(w);
  for (let y = 0; y < h; ++y) {
    const row = y * w;
    const up = y > 0 ? mask.subarray(row - w, row) : zeros;
    const trow = Math.floor(y / B) * bw;
    for (let bx = 0; bx < bw; ++bx) {
      const x0 = bx * B, x1 = Math.min(w, x0 + B);
      if (types[trow + bx] === 1) {
        mask.fill(255, row + x0, row + x1);
        continue;
      }
      if (types[trow + bx] !== 2) continue;
      let cur = (x0 >= 1 && mask[row + x0 - 1] ? 1 : 0) | (x0 >= 2 && mask[row + x0 - 2] ? 2 : 0) |
        (x0 >= 3 && mask[row + x0 - 3] ? 4 : 0);
      let upc = (x0 + 1 < w && up[x0 + 1] ? 1 : 0) | (up[x0] ? 2 : 0) | (x0 >= 1 && up[x0 - 1] ? 4 : 0);
      for (let x = x0; x < x1; ++x) {
        const bit = dec.get(probs, cur | (upc << 3));
        mask[row + x] = bit ? 255 : 0;
        cur = ((cur << 1) | bit) & 7;
        upc = ((upc << 1) | (x + 2 < w && up[x + 2] ? 1 : 0)) & 7;
      }
    }
    if (dec.pastEnd) fail(`v1.mask: coded blocks end early, at row ${y}`);
  }
  if (dec.pos !== data.length) fail(`v1.mask: ${data.length - dec.pos} bytes after the coded blocks`);
  return mask;
}

// The zstd row format (PROTOCOL.md §8 "Mask rows", the box = the image).
function decodeMaskRows(zmask, w, h) {
  const rle = unzstdRows(zmask, w, h, 'v1.mask', 'image');
  const mask = new Uint8Array(w * h);
  const st = { p: 0 };
  let prev = [];
  for (let y = 0; y < h; ++y) {
    const head = getVarint(rle, st);
    if (head < 0) fail(`v1.mask: row ${y} ends early`);
    const cur = [];
    if (head === 0) {
      for (let i = 0; i < prev.length; ++i) {
        const z = getVarint(rle, st);
        if (z < 0) fail(`v1.mask: row ${y} ends early`);
        const t = prev[i] + (z % 2 ? -(z + 1) / 2 : z / 2);
        if (t < 0 || t >= w || (i > 0 && t <= cur[i - 1])) fail(`v1.mask: row ${y} transition ${i} out of order or outside the row`);
        cur.push(t);
      }
    } else {
      if (head - 1 > w) fail(`v1.mask: row ${y} has ${head - 1} transitions`);
      let t = -1;
      for (let i = 0; i + 1 < head; ++i) {
        const g = getVarint(rle, st);
        if (g < 0) fail(`v1.mask: row ${y} ends early`);
        t = i === 0 ? g : t + g + 1;
        if (t >= w) fail(`v1.mask: row ${y} transition ${i} outside the row`);
        cur.push(t);
      }
    }
    for (let i = 0; i < cur.length; i += 2) mask.fill(255, y * w + cur[i], y * w + (i + 1 < cur.length ? cur[i + 1] : w));
    prev = cur;
  }
  if (st.p !== rle.length) fail(`v1.mask: ${rle.length - st.p} bytes after the last row`);
  return mask;
}

// The blob's mask: Uint8Array(width × height), 255 foreground, 0 background.
// Foreground outside the picture's window is a violation.
export function decodeVideoMask(info) {
  const m = info.maskBlocks ? decodeMaskBlocks(info.mask, info.width, info.height)
    : decodeMaskRows(info.mask, info.width, info.height);
  const { x, y, w, h } = info.window, W = info.width;
  for (let row = 0; row < info.height; ++row) {
    const inside = row >= y && row < y + h;
    const o = row * W;
    const bad = inside ? m.subarray(o, o + x).some((v) => v) || m.subarray(o + x + w, o + W).some((v) => v)
      : m.subarray(o, o + W).some((v) => v);
    if (bad) fail(`v1.mask: foreground in row ${row} outside the window ${w}x${h} at ${x},${y}`);
  }
  return m;
}

// ------------------------------------------------------------ picture

// WebCodecs' codec string from the keyframe's SPS (Annex B): avc1.PPCCLL.
export function h264CodecString(annexB) {
  for (let i = 0; i + 6 < annexB.length; ++i) {
    if (annexB[i] === 0 && annexB[i + 1] === 0 && annexB[i + 2] === 1 && (annexB[i + 3] & 0x1f) === 7) {
      const hex = (v) => v.toString(16).padStart(2, '0').toUpperCase();
      return `avc1.${hex(annexB[i + 4])}${hex(annexB[i + 5])}${hex(annexB[i + 6])}`;
    }
  }
  return fail('v1.video: the keyframe has no sequence parameter set');
}

// A picture is read back unless more than this many newer blobs of its
// stream were handed over before it came out: the viewer is then behind and
// catches up. (The rule was "any newer blob": a live stream hands over a blob
// every 33 ms while eight pods' pictures take longer to come out, so nearly
// every picture was skipped and a live G3 + V1 broadcast showed a grey
// person; a still or a test that waits for each picture never saw it.)
export const SKIP_BEHIND = 2;

// How long a picture may stay inside the decoder: a delta frame that finds
// an older one still inside (with newer ones after it) is not decoded, nor
// are the next ones up to a key frame (they need it), and the decoder is
// flushed so that the pictures inside come out at once. A machine that
// decodes slower than the stream comes thus shows colour at most about this
// long plus a key-frame interval late, refreshed after every key frame,
// instead of queueing without end (measured: headless Chromium rendering on
// 2 cores decoded ~37 pictures a second where eight pods at 30 fps hand over
// 240; the colour was 4.4 s behind the geometry and growing). Age, not a
// count: a join or a catch-up hands a burst of pictures over at once, which
// a count took for falling behind (a still then lost its colour).
export const MAX_IN_DECODER_MS = 1000;

// How long a handed-over picture may stay inside the decoder, with nothing
// newer after it, before the decoder is flushed (a 30 fps stream hands over
// a picture every 33 ms; a still or a stalled edge hands over none).
const HOLD_MS = 1000;

// One pod's V1 stream, decoded in order by the browser's VideoDecoder.
// decode(blob) must be called in the stream's order; it hands the picture to
// the decoder at once (pictures are decoded one after another while the
// caller waits) and resolves to {width, height, rgba, box} as decodeColor
// does (alpha = the mask, background 0); to null while the stream waits for
// a keyframe (joined mid-stream, a gap, or an error); or to {skipped: true}
// when more than SKIP_BEHIND newer blobs of the stream were handed over
// before this one's picture came out: it is decoded (the next one needs it)
// but not read back, so a viewer that falls behind catches up instead of
// queueing more.
export class VideoColorStream {
  constructor({ skipBehind = SKIP_BEHIND, maxInDecoderMs = MAX_IN_DECODER_MS } = {}) {
    this.skipBehind = skipBehind;
    this.maxInDecoderMs = maxInDecoderMs;
    this.decoder = null;
    this.config = '';
    this.synced = false;
    this.lastFrame = 0;
    this.size = '';     // the stream's image and picture sizes (a delta frame must keep them)
    this.waiting = [];  // {ts, t (handed at, ms), decoder, resolve, reject} of the pictures handed over, in order
    this.handed = 0;    // pictures handed to the decoder so far
    this.flushes = 0;   // pictures flushed out after HOLD_MS (see decode)
    this.dropped = 0;   // delta frames not decoded because the decoder was behind (MAX_IN_DECODER_MS)
  }

  close() {
    if (this.decoder && this.decoder.state !== 'closed') this.decoder.close();
    this.decoder = null;
    this.synced = false;
    for (const w of this.waiting.splice(0)) w.reject(new Error('stream closed'));
  }

  decode(blob) {
    let info, mask, size;
    try {
      info = parseVideoBlob(blob);
      size = `${info.width}x${info.height} ${info.window.w}x${info.window.h}`;
      if (!info.keyframe && (!this.synced || info.frameNumber !== ((this.lastFrame + 1) >>> 0) || size !== this.size)) {
        this.synced = false;
        return Promise.resolve(null);
      }
      mask = decodeVideoMask(info);
      if (info.library !== 1) fail('v1.library: this page decodes H.264 only');
      if (info.keyframe) this._configure(info);
    } catch (e) {
      this.synced = false;
      return Promise.reject(e);
    }
    if (!this.decoder || this.decoder.state !== 'configured') {
      this.synced = false;
      return Promise.resolve(null);
    }
    const now = performance.now();
    // Behind: a picture handed over long ago still inside with newer ones
    // after it (one picture alone may simply wait for more input, see below).
    if (!info.keyframe && this.waiting.length > 1 && now - this.waiting[0].t > this.maxInDecoderMs) {
      this.synced = false;
      this.dropped++;
      // Only the pictures inside now: a key frame may be handed to the same
      // decoder before the flush returns, and its pictures must not be
      // settled as lost with these (they were: a still lost its colour).
      const behind = this.decoder, upTo = this.handed + 1;
      behind.flush().catch(() => {}).finally(() => this._settle(behind, upTo));
      return Promise.resolve(null);
    }
    // Pictures are matched to their blobs by timestamp (the count of
    // pictures handed over), not by order: a picture the decoder never
    // returns must not shift every later one onto the wrong frame.
    const seq = ++this.handed;
    const decoder = this.decoder;
    const picture = new Promise((resolve, reject) => this.waiting.push({ ts: seq, t: now, decoder, resolve, reject }));
    try {
      this.decoder.decode(new EncodedVideoChunk({ type: info.keyframe ? 'key' : 'delta', timestamp: seq,
        data: info.video }));
    } catch (e) {
      this.waiting.pop();
      this.synced = false;
      return Promise.reject(new DecodeError(`v1.video: the browser's decoder refused frame ${info.frameNumber} (${e.message})`));
    }
    this.synced = true;
    this.lastFrame = info.frameNumber;
    this.size = size;
    // A decoder may keep the newest picture until more input comes (seen
    // now and then on a loaded machine: the picture of a still, or the one a
    // caller awaits before handing over the next, never came out). When
    // nothing newer has been handed over after HOLD_MS, flush it out; a
    // flushed decoder needs a key frame next, so the stream waits for one.
    const timer = setTimeout(() => {
      if (seq !== this.handed || decoder !== this.decoder || decoder.state !== 'configured') return;
      if (!this.waiting.some((w) => w.ts === seq)) return;
      this.synced = false;
      this.flushes++;
      decoder.flush().catch(() => {}).finally(() => this._settle(decoder, seq + 1));
    }, HOLD_MS);
    picture.finally(() => clearTimeout(timer)).catch(() => {});
    return picture.then(async (frame) => {
      if (!frame) return { skipped: true };  // the decoder returned no picture for it
      try {
        if (this.handed - seq > this.skipBehind) return { skipped: true };
        const W = info.width, H = info.height;
        return { width: W, height: H, rgba: await frameToRgba(frame, W, H, info.window, mask), box: { ...info.window } };
      } finally {
        frame.close();
      }
    }, (e) => {
      throw new DecodeError(`v1.video: the browser's decoder failed on frame ${info.frameNumber} (${e.message || e})`);
    });
  }

  _configure(info) {
    const codec = h264CodecString(info.video);
    const config = `${codec} ${info.window.w}x${info.window.h}`;
    if (this.decoder && this.decoder.state === 'configured' && config === this.config) return;
    if (this.decoder && this.decoder.state === 'configured') {
      // A new picture size or level at a keyframe: a new decoder takes the
      // stream from here; the old one is flushed, so that the pictures
      // already handed to it still come out, then closed. (Closing it at once
      // dropped them; reconfiguring it in place sometimes never returned the
      // picture before the new size.)
      const old = this.decoder;
      old.flush().catch(() => {}).finally(() => {
        this._settle(old, null);
        if (old.state !== 'closed') old.close();
      });
    } else {
      this.close();
    }
    const decoder = new VideoDecoder({
      output: (frame) => {
        const i = this.waiting.findIndex((w) => w.ts === frame.timestamp);
        if (i < 0) {
          frame.close();
          return;
        }
        // Pictures handed to this decoder before this one never came out.
        this._settle(decoder, frame.timestamp);
        this.waiting.splice(this.waiting.findIndex((w) => w.ts === frame.timestamp), 1)[0].resolve(frame);
      },
      error: (e) => {
        if (decoder === this.decoder) this.synced = false;
        this._settle(decoder, null, e);
      },
    });
    decoder.configure({ codec, codedWidth: info.window.w, codedHeight: info.window.h, optimizeForLatency: true });
    this.decoder = decoder;
    this.config = config;
  }

  // Resolves to null (or rejects with `error`) the pictures handed to
  // `decoder` before timestamp `before` (all of them when null).
  _settle(decoder, before, error) {
    this.waiting = this.waiting.filter((w) => {
      if (w.decoder !== decoder || (before !== null && w.ts >= before)) return true;
      if (error) w.reject(error);
      else w.resolve(null);
      return false;
    });
  }
}

const clamp8 = (v) => (v < 0 ? 0 : v > 255 ? 255 : v);

// The decoded planes (the window `win` of the W×H image) to RGBA of the
// whole image with the C++ decoder's full-range BT.601 arithmetic
// (protocol/ycc.h, YccToRgbPixel), so that the page shows the colours the
// native viewer shows; background pixels 0, alpha = mask. Frames in another
// layout (a GPU frame) go through a canvas instead.
async function frameToRgba(frame, W, H, win, mask) {
  const rgba = new Uint8Array(W * H * 4);
  if (frame.format === 'I444' || frame.format === 'I420') {
    const buf = new Uint8Array(frame.allocationSize());
    const [ly, lu, lv] = await frame.copyTo(buf);
    const s = frame.format === 'I420' ? 1 : 0;
    for (let y = 0; y < win.h; ++y) {
      const py = ly.offset + y * ly.stride, pu = lu.offset + (y >> s) * lu.stride, pv = lv.offset + (y >> s) * lv.stride;
      const row = (win.y + y) * W + win.x;
      for (let x = 0, o = row * 4; x < win.w; ++x, o += 4) {
        if (!mask[row + x]) continue;
        const Y = buf[py + x], cb = buf[pu + (x >> s)] - 128, cr = buf[pv + (x >> s)] - 128;
        rgba[o] = clamp8(Y + ((91881 * cr + 32768) >> 16));
        rgba[o + 1] = clamp8(Y - ((22554 * cb + 46802 * cr - 32768) >> 16));
        rgba[o + 2] = clamp8(Y + ((116130 * cb + 32768) >> 16));
        rgba[o + 3] = 255;
      }
    }
    return rgba;
  }
  const canvas = new OffscreenCanvas(win.w, win.h);
  const g = canvas.getContext('2d', { willReadFrequently: true });
  g.drawImage(frame, 0, 0, win.w, win.h);
  const px = g.getImageData(0, 0, win.w, win.h, { colorSpace: 'srgb' }).data;
  for (let y = 0; y < win.h; ++y) {
    for (let x = 0; x < win.w; ++x) {
      const i = (win.y + y) * W + win.x + x, j = y * win.w + x;
      if (!mask[i]) continue;
      rgba[4 * i] = px[4 * j];
      rgba[4 * i + 1] = px[4 * j + 1];
      rgba[4 * i + 2] = px[4 * j + 2];
      rgba[4 * i + 3] = 255;
    }
  }
  return rgba;
}
