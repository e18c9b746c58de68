// The JavaScript decoders against the C++ ones: a recording written by the
// C++ encoders (holoport-web-fixture record) is parsed by web/src, its first
// MeshFrames and ColorFrames decoded, and the results compared with what
// the C++ decoders wrote (holoport-web-fixture golden): geometry exactly
// (positions, colours, triangles; recomputed normals within 1e-6), colour
// images within a JPEG-decoder tolerance (the page uses the browser's
// decoder; node uses jpeg-js) and masks exactly. The G3 blobs of the
// studio's foreground (golden --g3) likewise, and the marching-cubes table
// the JS generates against the C++ one. Then truncated prefixes and bit
// flips of every decoder's input must give a DecodeError (or, for a flip, a
// valid result), never another exception or a hang.
//
// Usage: node decoders_test.mjs RECORDING GOLDEN_DIR

import { readFileSync, readdirSync } from 'node:fs';
import { join } from 'node:path';
import jpeg from 'jpeg-js';
import { DecodeError } from '../src/bytes.js';
import { parseRecording, parseRecords, parseMeshFrame, parseColorFrame, parseRig, parseAudioPose, MSG } from '../src/protocol.js';
import { decodeGeometry } from '../src/geometry.js';
import { mcCases } from '../src/marching_cubes.js';
import { decodeColor } from '../src/color.js';
import { parseVideoBlob, decodeVideoMask, h264CodecString, VideoColorStream } from '../src/video.js';

const [recordingPath, goldenDir] = process.argv.slice(2);
if (!recordingPath || !goldenDir) {
  console.error('usage: node decoders_test.mjs RECORDING GOLDEN_DIR');
  process.exit(2);
}
let failures = 0;
function check(cond, what) {
  if (!cond) {
    failures++;
    console.log(`FAIL: ${what}`);
  }
}
const decodeJpeg = async (bytes) => {
  const img = jpeg.decode(bytes, { useTArray: true, formatAsRGBA: true });
  return { width: img.width, height: img.height, data: img.data };
};

const file = new Uint8Array(readFileSync(recordingPath));
const messages = parseRecording(file);
check(messages.length > 0 && messages[0].header.type === MSG.RIG, 'the recording starts with the Rig');
const rig = parseRig(messages[0].payload);
console.log(`recording: ${messages.length} messages, rig "${rig.name}" with ${rig.pods.length} pods`);

const golden = readdirSync(goldenDir);
const meshes = new Map(), colors = new Map();
for (const m of messages) {
  if (m.header.type === MSG.MESH) meshes.set(parseMeshFrame(m.payload).frameIndex, m);
  if (m.header.type === MSG.COLOR) colors.set(parseColorFrame(m.payload).frameIndex, m);
  if (m.header.type === MSG.AUDIO) parseAudioPose(m.payload, m.header);
}

// ---- geometry, exactly
function readGoldenMesh(name) {
  const b = readFileSync(join(goldenDir, name));
  const dv = new DataView(b.buffer, b.byteOffset, b.byteLength);
  const nv = dv.getUint32(0, true), nt = dv.getUint32(4, true), hasN = dv.getUint32(8, true), hasC = dv.getUint32(12, true);
  const take = (n) => {
    const a = b.buffer.slice(b.byteOffset + o, b.byteOffset + o + n);
    o += n;
    return a;
  };
  let o = 16;
  const pos = new Float32Array(take(nv * 12));
  const nrm = hasN ? new Float32Array(take(nv * 12)) : null;
  const col = hasC ? new Uint8Array(take(nv * 3)) : null;
  const idx = new Uint32Array(take(nt * 12));
  return { nv, nt, pos, nrm, col, idx };
}
function compareMesh(what, mesh, g) {
  const { nv, nt, pos, nrm, col, idx } = g;
  check(mesh.positions.length === nv * 3 && mesh.indices.length === nt * 3, `${what}: counts ${nv}/${nt}`);
  let posDiff = 0, idxDiff = 0, colDiff = 0, nrmMax = 0;
  for (let i = 0; i < nv * 3; ++i) if (mesh.positions[i] !== pos[i]) posDiff++;
  for (let i = 0; i < nt * 3; ++i) if (mesh.indices[i] !== idx[i]) idxDiff++;
  if (col) for (let i = 0; i < nv * 3; ++i) if (mesh.colors[i] !== col[i]) colDiff++;
  if (nrm) for (let i = 0; i < nv * 3; ++i) nrmMax = Math.max(nrmMax, Math.abs(mesh.normals[i] - nrm[i]));
  check(posDiff === 0, `${what}: ${posDiff} position components differ`);
  check(idxDiff === 0, `${what}: ${idxDiff} indices differ`);
  check(colDiff === 0 && !!col === !!mesh.colors, `${what}: ${colDiff} colour components differ`);
  check(!!nrm === !!mesh.normals && nrmMax <= 1e-6, `${what}: normals differ by ${nrmMax}`);
  return nrmMax;
}
const median = (a) => [...a].sort((x, y) => x - y)[a.length >> 1];
// Cold: the first call per frame (the G1 figure before G3 was the median of
// these); warm: below, once every frame has been checked.
function timeDecode(blob, cold) {
  const t0 = performance.now();
  const mesh = decodeGeometry(blob);
  cold.push(performance.now() - t0);
  return mesh;
}
// The median of 5 calls after 10 more, once the JIT has optimized the code.
function warmMs(blob) {
  for (let i = 0; i < 10; ++i) decodeGeometry(blob);
  const t = [];
  for (let i = 0; i < 5; ++i) {
    const t0 = performance.now();
    decodeGeometry(blob);
    t.push(performance.now() - t0);
  }
  return median(t);
}
let meshChecked = 0;
const geometryMs = [], g1Blobs = [];
for (const g of golden.filter((f) => f.startsWith('mesh_'))) {
  const k = Number(g.slice(5, -4));
  const gm = readGoldenMesh(g);
  const mf = parseMeshFrame(meshes.get(k).payload);
  const mesh = timeDecode(mf.data, geometryMs);
  const nrmMax = compareMesh(`frame ${k}`, mesh, gm);
  console.log(`geometry frame ${k}: ${mf.data.length} bytes, ${gm.nv} vertices, ${gm.nt} triangles; ` +
    `positions/indices/colours identical, normals max diff ${nrmMax.toExponential(1)}; ` +
    `decode ${geometryMs.at(-1).toFixed(1)} ms cold`);
  g1Blobs.push(mf.data);
  meshChecked++;
}
check(meshChecked >= 1, 'golden meshes were found');

// ---- G3: the marching-cubes table, then the studio's foreground, exactly
const mcGolden = readFileSync(join(goldenDir, 'mc_table.bin'));
const cases = mcCases();
let mcDiff = 0;
for (let i = 0; i < 256; ++i) {
  const n = mcGolden[37 * i], e = mcGolden.subarray(37 * i + 1, 37 * i + 1 + 3 * n);
  if (cases[i].length !== 3 * n || e.some((v, j) => v !== cases[i][j])) mcDiff++;
}
check(mcDiff === 0, `marching cubes: ${mcDiff} of 256 cases differ from common/marching_cubes_table.cc`);
console.log(`marching cubes: the generated table equals the C++ one in ${256 - mcDiff} of 256 cases`);
const g3Blobs = [], g3Ms = [];
for (const g of golden.filter((f) => f.startsWith('g3_')).sort()) {
  const k = Number(g.slice(3, -5));
  const blob = new Uint8Array(readFileSync(join(goldenDir, g)));
  const gm = readGoldenMesh(`g3mesh_${k}.bin`);
  const mesh = timeDecode(blob, g3Ms);
  const nrmMax = compareMesh(`g3 frame ${k}`, mesh, gm);
  console.log(`g3 frame ${k}: ${blob.length} bytes, ${gm.nv} vertices, ${gm.nt} triangles; ` +
    `positions/indices identical, normals max diff ${nrmMax.toExponential(1)}; ` +
    `decode ${g3Ms.at(-1).toFixed(1)} ms cold`);
  g3Blobs.push(blob);
}
check(g3Blobs.length >= 1, 'golden G3 blobs were found');
const geometryWarmMs = g1Blobs.map(warmMs), g3WarmMs = g3Blobs.map(warmMs);
const list = (a) => a.map((t) => t.toFixed(1)).join(' / ');
console.log(`geometry decode, warm (median of 5 calls after 10): G1 frames ${list(geometryWarmMs)} ms; ` +
  `G3 frames ${list(g3WarmMs)} ms`);

// ---- colour, within tolerance; masks exactly
let colorChecked = 0, worst = 0, sumAbs = 0, count = 0;
for (const g of golden.filter((f) => f.startsWith('color_'))) {
  const [, k, pod] = g.slice(0, -4).split('_').map(Number);
  const b = readFileSync(join(goldenDir, g));
  const w = b.readUInt32LE(0), h = b.readUInt32LE(4);
  const cf = parseColorFrame(colors.get(k).payload);
  const im = cf.images.find((x) => x.podId === pod);
  const img = await decodeColor(im.data, decodeJpeg);
  check(img.width === w && img.height === h, `colour ${k}/${pod}: size`);
  let maskDiff = 0;
  for (let i = 0; i < w * h; ++i) {
    const a = img.rgba[4 * i + 3], e = b[8 + 4 * i + 3];
    if (a !== e) maskDiff++;
    if (e) {
      for (let c = 0; c < 3; ++c) {
        const d = Math.abs(img.rgba[4 * i + c] - b[8 + 4 * i + c]);
        worst = Math.max(worst, d);
        sumAbs += d;
        count++;
      }
    } else {
      for (let c = 0; c < 3; ++c) if (img.rgba[4 * i + c] !== 0) maskDiff++;
    }
  }
  check(maskDiff === 0, `colour ${k}/${pod}: ${maskDiff} mask or background pixels differ`);
  colorChecked++;
}
const meanAbs = count ? sumAbs / count : 0;
console.log(`colour: ${colorChecked} pod images; masks identical; foreground |diff| mean ${meanAbs.toFixed(3)}, max ${worst}`);
check(colorChecked >= 1, 'golden colour images were found');
check(meanAbs <= 1.0 && worst <= 8, `colour differs from libjpeg's decode by mean ${meanAbs}, max ${worst}`);

// ---- malformed input: truncations and bit flips give DecodeError, nothing else
function expectDecodeError(fn, what) {
  try {
    fn();
  } catch (e) {
    if (e instanceof DecodeError) return true;
    check(false, `${what}: threw ${e.name}: ${e.message}`);
    return false;
  }
  return false;
}
async function expectDecodeErrorAsync(fn, what) {
  try {
    await fn();
  } catch (e) {
    if (e instanceof DecodeError) return true;
    check(false, `${what}: threw ${e.name}: ${e.message}`);
    return false;
  }
  return false;
}
function validMesh(m) {
  const nv = m.positions.length / 3;
  for (const i of m.indices) if (i >= nv) return false;
  for (const p of m.positions) if (!Number.isFinite(p)) return false;
  return true;
}
let rng = 12345;
const rand = (n) => {
  rng = (rng * 1103515245 + 12345) % 2147483648;
  return rng % n;
};
// The first G1 frame and the first G3 blob.
const geometryInputs = [['g1', parseMeshFrame(meshes.values().next().value.payload).data]];
if (g3Blobs.length) geometryInputs.push(['g3', g3Blobs[0]]);
for (const [name, firstMesh] of geometryInputs) {
  // Prefixes: all of the first 512 bytes, then 300 spread over the rest.
  const prefixes = new Set();
  for (let n = 0; n < Math.min(512, firstMesh.length); ++n) prefixes.add(n);
  for (let i = 0; i < 300; ++i) prefixes.add(Math.floor((firstMesh.length * i) / 300));
  let refused = 0;
  for (const n of prefixes) {
    if (n >= firstMesh.length) continue;
    const blob = firstMesh.slice(0, n);
    if (expectDecodeError(() => decodeGeometry(blob), `${name} prefix ${n}`)) refused++;
    else check(false, `${name} prefix ${n} of ${firstMesh.length} bytes was accepted`);
  }
  let flipsOk = 0;
  for (let i = 0; i < 300; ++i) {
    const blob = firstMesh.slice();
    blob[rand(blob.length)] ^= 1 << rand(8);
    let m = null;
    if (!expectDecodeError(() => { m = decodeGeometry(blob); }, `${name} flip ${i}`) && m) {
      check(validMesh(m), `${name} flip ${i}: decoded an invalid mesh`);
      flipsOk++;
    }
  }
  console.log(`geometry ${name}: ${refused} truncated prefixes refused; 300 bit flips: ${300 - flipsOk} refused, ${flipsOk} decoded to valid meshes`);
}

const firstColor = parseColorFrame(colors.values().next().value.payload).images[0].data;
let cRefused = 0;
for (let n = 0; n < firstColor.length; n += Math.max(1, Math.floor(firstColor.length / 400))) {
  const blob = firstColor.slice(0, n);
  if (await expectDecodeErrorAsync(() => decodeColor(blob, decodeJpeg), `colour prefix ${n}`)) cRefused++;
  else check(false, `colour prefix ${n} of ${firstColor.length} bytes was accepted`);
}
for (let i = 0; i < 200; ++i) {
  const blob = firstColor.slice();
  // Flip in the header, box and mask (the JPEG's own bytes go to the browser's decoder).
  blob[rand(Math.min(blob.length, 64))] ^= 1 << rand(8);
  try {
    await decodeColor(blob, decodeJpeg);
  } catch (e) {
    if (!(e instanceof DecodeError)) check(false, `colour flip ${i}: threw ${e.name}: ${e.message}`);
  }
}
console.log(`colour: ${cRefused} truncated prefixes refused; 200 bit flips in the header and mask handled`);

// V1 masks (golden v1_K_blocks|rows.bin, v1mask_K.bin): exactly the C++
// decoder's mask in both formats; every prefix of a blob and of its mask
// bytes refused; bit flips in the mask refused or decoded to a whole mask.
{
  let v1Checked = 0;
  const v1Blobs = [];
  for (const g of golden.filter((f) => f.startsWith('v1_')).sort()) {
    const k = g.split('_')[1];
    const want = new Uint8Array(readFileSync(join(goldenDir, `v1mask_${k}.bin`)));
    const w = new DataView(want.buffer, want.byteOffset).getUint32(0, true), h = new DataView(want.buffer, want.byteOffset).getUint32(4, true);
    const blob = new Uint8Array(readFileSync(join(goldenDir, g)));
    const info = parseVideoBlob(blob);
    check(info.width === w && info.height === h, `${g}: size ${info.width}x${info.height}`);
    check(info.maskBlocks === g.includes('blocks'), `${g}: mask format flag`);
    check(info.keyframe === (k === '0'), `${g}: keyframe flag`);
    if (k === '0') check(/^avc1\.F4[0-9A-F]{4}$/.test(h264CodecString(info.video)), `${g}: codec ${h264CodecString(info.video)}`);
    const mask = decodeVideoMask(info);
    let diff = 0;
    for (let i = 0; i < w * h; ++i) diff += mask[i] !== want[8 + i];
    check(diff === 0, `${g}: mask differs from the C++ decode in ${diff} pixels`);
    v1Checked++;
    v1Blobs.push([g, blob]);
  }
  check(v1Checked >= 2, 'golden V1 blobs were found');
  // The picture's window (flag bit 3): parsed as the C++ encoder wrote it;
  // a window that cuts the foreground, is odd-sized or leaves the image is refused.
  {
    const [g, blob] = v1Blobs[0];
    const info = parseVideoBlob(blob);
    const win = info.window;
    check((info.flags & 8) !== 0 && win.w * win.h < info.width * info.height, `${g}: window ${JSON.stringify(win)}`);
    const at = 11;  // codec, flags, width, height, library, frame number
    const rewrite = (x, y, w, h) => {
      const b = blob.slice();
      const dv = new DataView(b.buffer);
      [x, y, w, h].forEach((v, i) => dv.setUint16(at + 2 * i, v, true));
      return b;
    };
    check(JSON.stringify(parseVideoBlob(rewrite(win.x, win.y, win.w, win.h)).window) === JSON.stringify(win),
      'window rewrite is sound');
    const bad = [[win.x, win.y, win.w + 1, win.h, 'v1.window'], [win.x, win.y, 0, win.h, 'v1.window'],
      [info.width - 2, win.y, 16, win.h, 'v1.window'], [win.x, win.y, win.w, 2, 'outside the window']];
    for (const [x, y, w, h, field] of bad) {
      let msg = '';
      try {
        decodeVideoMask(parseVideoBlob(rewrite(x, y, w, h)));
      } catch (e) {
        msg = e instanceof DecodeError ? e.message : `threw ${e.name}`;
      }
      check(msg.includes(field), `window ${x},${y} ${w}x${h}: ${msg || 'accepted'}`);
    }
  }
  let v1Refused = 0, v1FlipsOk = 0, v1Prefixes = 0;
  for (const [g, blob] of v1Blobs.slice(0, 2)) {
    for (let n = 0; n < blob.length; n += Math.max(1, Math.floor(blob.length / 300))) {
      v1Prefixes++;
      if (expectDecodeError(() => decodeVideoMask(parseVideoBlob(blob.slice(0, n))), `${g} prefix ${n}`)) v1Refused++;
      else check(false, `${g} prefix ${n} of ${blob.length} bytes was accepted`);
    }
    const info = parseVideoBlob(blob);
    // Cut mask bytes inside an otherwise whole blob: the mask decoder itself must notice.
    for (let cut = 1; cut < info.mask.length; cut += Math.max(1, Math.floor(info.mask.length / 100))) {
      const m = info.mask.slice(0, info.mask.length - cut);
      if (!expectDecodeError(() => decodeVideoMask({ ...info, mask: m }), `${g} mask cut ${cut}`)) {
        check(false, `${g}: mask cut by ${cut} bytes was accepted`);
      }
    }
    for (let i = 0; i < 200; ++i) {
      const m = info.mask.slice();
      m[rand(m.length)] ^= 1 << rand(8);
      let out = null;
      if (!expectDecodeError(() => { out = decodeVideoMask({ ...info, mask: m }); }, `${g} mask flip ${i}`) && out) {
        check(out.length === info.width * info.height, `${g} mask flip ${i}: a mask of the wrong size`);
        v1FlipsOk++;
      }
    }
  }
  console.log(`v1: ${v1Checked} golden masks exact; ${v1Refused} of ${v1Prefixes} prefixes refused; 400 mask bit flips: ` +
    `${400 - v1FlipsOk} refused, ${v1FlipsOk} decoded to whole masks`);
}

// Records: every prefix of the first part-sized run of records is refused or parses whole records.
const recs = file.subarray(64, 64 + Math.min(file.length - 64, 4096));
let recRefused = 0;
for (let n = 1; n < recs.length; n += 7) {
  if (expectDecodeError(() => parseRecords(recs.subarray(0, n)), `records prefix ${n}`)) recRefused++;
}
console.log(`records: ${recRefused} truncated runs refused`);
// Lean AudioPose (codec 3): PROTOCOL.md §9.1's example, byte for byte (the
// C++ side pins the same bytes in tests/audio/lean_frame_test.cc).
{
  const lean = Uint8Array.from([0x03, 0x01, 0xd2, 0x04, 0x0c, 0xfe, 0x40, 0x06, 0x00, 0x40, 0xed, 0xfb, 0x00, 0x00,
    0xf8, 0xff, 0xfe]);
  const header = { type: MSG.AUDIO, sequence: 42, captureUs: 1000000 };
  const a = parseAudioPose(lean, header);
  check(a.codec === 3 && a.sequence === 42 && a.captureUs === 1000000 && a.sampleRate === 48000 && a.channels === 1,
    `lean frame: fields ${JSON.stringify({ codec: a.codec, sequence: a.sequence, captureUs: a.captureUs })}`);
  check(a.hasPose && Math.abs(a.pose.x - 1.234) < 1e-9 && Math.abs(a.pose.y + 0.5) < 1e-9 && Math.abs(a.pose.z - 1.6) < 1e-9,
    `lean frame: position ${a.pose && [a.pose.x, a.pose.y, a.pose.z]}`);
  check(Math.abs(a.pose.yaw - Math.PI / 2) < 1e-9 && Math.abs(a.pose.pitch + 0.1) < 1e-4 && a.pose.roll === 0,
    `lean frame: angles ${a.pose && [a.pose.yaw, a.pose.pitch, a.pose.roll]}`);
  check(a.audio.length === 3 && a.audio[0] === 0xf8, 'lean frame: the Opus packet is the rest of the payload');
  const bare = parseAudioPose(Uint8Array.from([0x03, 0x00, 0xf8, 0xff, 0xfe]), header);
  check(!bare.hasPose && bare.pose === null && bare.audio.length === 3, 'lean frame without a pose');
  check(expectDecodeError(() => parseAudioPose(lean), 'lean without header'), 'a lean frame without its header is refused');
  let leanRefused = 0;
  for (let n = 0; n < lean.length; ++n) {
    // Cut before the Opus packet: refused; within it: a shorter packet (valid on this layer).
    if (expectDecodeError(() => parseAudioPose(lean.slice(0, n), header), `lean prefix ${n}`)) leanRefused++;
    else check(n > 14, `lean prefix ${n} was accepted`);
  }
  check(leanRefused === 15, `lean: ${leanRefused} of 15 prefixes without Opus bytes refused`);
  let leanFlipsOk = 0;
  for (let i = 0; i < lean.length * 8; ++i) {
    const b = lean.slice();
    b[i >> 3] ^= 1 << (i & 7);
    let f = null;
    if (!expectDecodeError(() => { f = parseAudioPose(b, header); }, `lean flip ${i}`) && f) {
      const p = f.pose || { x: 0, y: 0, z: 0, yaw: 0, pitch: 0, roll: 0 };
      check([p.x, p.y, p.z, p.yaw, p.pitch, p.roll].every(Number.isFinite) && f.audio.length >= 1,
        `lean flip ${i}: decoded an invalid frame`);
      leanFlipsOk++;
    }
  }
  console.log(`lean audio_pose: ${leanRefused} truncated prefixes refused; ${lean.length * 8} bit flips: ` +
    `${lean.length * 8 - leanFlipsOk} refused, ${leanFlipsOk} decoded to valid frames`);
}

// A decoder that keeps its newest picture until more input comes (as the
// browser's did now and then on a loaded machine: a still's colour never
// showed). A fake VideoDecoder that outputs a picture only when the next
// chunk or a flush arrives: a picture with nothing after it comes out
// through a flush after the stream's hold time, and the stream then waits
// for a key frame; pictures followed by newer ones are never flushed.
{
  const key = new Uint8Array(readFileSync(join(goldenDir, 'v1_0_blocks.bin')));
  const delta = new Uint8Array(readFileSync(join(goldenDir, 'v1_1_blocks.bin')));
  const win = parseVideoBlob(key).window;
  const fakeFrame = (timestamp) => ({
    timestamp, format: 'I444', allocationSize: () => win.w * win.h * 3, close() {},
    copyTo: async () => [0, 1, 2].map((p) => ({ offset: p * win.w * win.h, stride: win.w })),
  });
  let flushCalls = 0;
  globalThis.EncodedVideoChunk = class { constructor(init) { Object.assign(this, init); } };
  globalThis.VideoDecoder = class {
    constructor({ output }) { this.output = output; this.state = 'unconfigured'; this.decodeQueueSize = 0; this.held = null; }
    configure() { this.state = 'configured'; }
    decode(chunk) {
      if (this.held !== null) this.output(fakeFrame(this.held));
      this.held = chunk.timestamp;
    }
    async flush() {
      flushCalls++;
      if (this.held !== null) this.output(fakeFrame(this.held));
      this.held = null;
    }
    close() { this.state = 'closed'; }
  };
  const within = (promise, ms) => Promise.race([promise, new Promise((r) => setTimeout(() => r('timed out'), ms))]);
  // Alone: the picture comes out through a flush.
  const alone = new VideoColorStream();
  const t0 = Date.now();
  const picture = await within(alone.decode(key), 5000);
  check(picture && picture.rgba && picture.width === parseVideoBlob(key).width,
    `a picture with nothing after it comes out (got ${picture === 'timed out' ? 'nothing in 5 s' : JSON.stringify(picture)})`);
  check(alone.flushes === 1 && flushCalls === 1, `it came out through one flush (${alone.flushes}, ${flushCalls})`);
  const waited = Date.now() - t0;
  check(waited >= 900 && waited < 3000, `after the hold time (${waited} ms)`);
  check((await within(alone.decode(delta), 3000)) === null, 'after a flush the stream waits for a key frame');
  alone.close();
  // In a stream: each picture comes out when the next is handed over; no
  // flush. One blob behind is how such a decoder works, not a viewer falling
  // behind: the picture is read back (skipping it left a live V1 broadcast
  // without colour).
  const streaming = new VideoColorStream();
  const first = streaming.decode(key);
  const second = streaming.decode(delta);
  const r1 = await within(first, 3000);
  check(r1 && r1.rgba, `a picture out one blob behind is read back (${r1 && r1.skipped ? 'skipped' : typeof r1})`);
  await new Promise((r) => setTimeout(r, 1200));
  check(streaming.flushes === 1, `the newest picture, alone after the hold time, is flushed (${streaming.flushes})`);
  const r2 = await within(second, 3000);
  check(r2 && r2.rgba, 'and comes out');
  streaming.close();
  // A viewer that falls behind: more than skipBehind newer blobs handed over
  // before a picture comes out → decoded but not read back.
  const delta2 = new Uint8Array(readFileSync(join(goldenDir, 'v1_2_blocks.bin')));
  const behind = new VideoColorStream({ skipBehind: 1 });
  const p1 = behind.decode(key), p2 = behind.decode(delta), p3 = behind.decode(delta2);
  const b1 = await within(p1, 3000), b2 = await within(p2, 3000);
  check(b1 && b1.skipped === true, `a picture two blobs behind (limit 1) is skipped (${JSON.stringify(b1 && Object.keys(b1))})`);
  check(b2 && b2.rgba, 'one blob behind is read back');
  const b3 = await within(p3, 3000);
  check(b3 && b3.rgba, 'the newest comes out (flushed) and is read back');
  behind.close();
  // A decoder slower than the stream (here: one that returns nothing until
  // flushed): once a picture has been inside longer than maxInDecoderMs, the
  // next delta is not handed over, the decoder is flushed so the pictures
  // inside come out at once, and the stream waits for a key frame. A burst
  // handed over at once is not "behind".
  globalThis.VideoDecoder = class {
    constructor({ output }) { this.output = output; this.state = 'unconfigured'; this.decodeQueueSize = 0; this.held = []; }
    configure() { this.state = 'configured'; }
    decode(chunk) { this.held.push(chunk.timestamp); }
    async flush() {
      flushCalls++;
      for (const t of this.held.splice(0)) this.output(fakeFrame(t));
    }
    close() { this.state = 'closed'; }
  };
  const slow = new VideoColorStream({ maxInDecoderMs: 200 });
  const s1 = slow.decode(key), s2 = slow.decode(delta);
  check(slow.dropped === 0, 'a burst is decoded');
  await new Promise((r) => setTimeout(r, 300));
  const t1 = Date.now();
  const s3p = slow.decode(delta2);  // behind: not decoded, the decoder flushed
  const s4p = slow.decode(delta);   // the stream now waits for a key frame
  const k2p = slow.decode(key);     // which comes before the flush has returned
  const s3 = await within(s3p, 3000);
  check(s3 === null && slow.dropped === 1, `the delta that finds the decoder behind is not decoded (${s3}, dropped ${slow.dropped})`);
  const [o1, o2] = [await within(s1, 3000), await within(s2, 3000)];
  check(o1 && o1.rgba && o2 && o2.rgba, 'the pictures inside come out and are read back');
  check(Date.now() - t1 < 500, `at once, not after the hold time (${Date.now() - t1} ms)`);
  check((await within(s4p, 3000)) === null, 'then the stream waits for a key frame');
  const k2 = await within(k2p, 3000);
  check(k2 && k2.rgba, `and resumes at it: the key frame handed while the flush ran is not settled with it (${JSON.stringify(k2 && Object.keys(k2))})`);
  slow.close();
  delete globalThis.VideoDecoder;
  delete globalThis.EncodedVideoChunk;
  console.log(`v1 stream: a held picture flushed out after ${waited} ms`);
}

const ms = (a) => (a.length ? Number(median(a).toFixed(2)) : null);
console.log(JSON.stringify({ figure: 'web_decode_node', geometry_ms_median: ms(geometryMs),
  geometry_warm_ms_median: ms(geometryWarmMs), g3_ms_median: ms(g3Ms), g3_warm_ms_median: ms(g3WarmMs) }));

if (failures) {
  console.log(`${failures} failure(s)`);
  process.exit(1);
}
console.log('decoders: all checks passed');
