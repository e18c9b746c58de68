// The marching-cubes case table of common/marching_cubes_table.cc, generated
// here from the same rule as there (G3 must triangulate every cube as the
// C++ decoder does, and the rule is shorter and easier to check than 256
// literal cases): per sign pattern, the crossings on each cube face are
// joined into segments (a face with two diagonal inside corners cuts each
// one off on its own), the segments are chained into loops, and each loop is
// fanned from the vertex whose fan folds least. The fan choice compares
// float scores, so they are computed in float32 steps as the C++ does.
//
// Corner c sits at (c & 1, c >> 1 & 1, c >> 2 & 1); edge e runs along axis
// EDGE_AXIS[e] from corner EDGE_LOW[e]; a case's bit c is set when corner c
// is inside (value < 0); triangles are counter-clockwise seen from outside.

export const MC_MAX_TRIANGLES = 12;
export const EDGE_LOW = new Uint8Array(12);
export const EDGE_AXIS = new Uint8Array(12);
for (let a = 0; a < 3; ++a) {
  let k = 0;
  for (let c = 0; c < 8; ++c) {
    if ((c >> a) & 1) continue;
    EDGE_LOW[4 * a + k] = c;
    EDGE_AXIS[4 * a + k] = a;
    ++k;
  }
}

const f = Math.fround;
const corner = (c) => [c & 1, (c >> 1) & 1, (c >> 2) & 1];
const edgeMid = (e) => {
  const p = corner(EDGE_LOW[e]);
  p[EDGE_AXIS[e]] += 0.5;
  return p;
};
const sub = (a, b) => [f(a[0] - b[0]), f(a[1] - b[1]), f(a[2] - b[2])];
const cross = (a, b) => [
  f(f(a[1] * b[2]) - f(a[2] * b[1])),
  f(f(a[2] * b[0]) - f(a[0] * b[2])),
  f(f(a[0] * b[1]) - f(a[1] * b[0])),
];
// Eigen sums a fixed-size 3-vector as x + (y + z).
const dot = (a, b) => f(f(a[0] * b[0]) + f(f(a[1] * b[1]) + f(a[2] * b[2])));
const norm = (a) => f(Math.sqrt(dot(a, a)));

function buildCase(index) {
  const inside = (c) => ((index >> c) & 1) !== 0;
  const crossed = (e) => inside(EDGE_LOW[e]) !== inside(EDGE_LOW[e] | (1 << EDGE_AXIS[e]));
  const next = new Int8Array(12).fill(-1);
  for (let a = 0; a < 3; ++a) {
    for (let side = 0; side < 2; ++side) {
      const normal = [0, 0, 0];
      normal[a] = side ? 1 : -1;
      const faceEdges = [], cuts = [];
      for (let e = 0; e < 12; ++e) {
        if (EDGE_AXIS[e] === a || ((EDGE_LOW[e] >> a) & 1) !== side) continue;
        faceEdges.push(e);
        if (crossed(e)) cuts.push(e);
      }
      // Segments [from, to, the corner on the side the segment cuts off].
      const segs = [];
      if (cuts.length === 2) {
        segs.push([cuts[0], cuts[1], EDGE_LOW[cuts[0]]]);
      } else if (cuts.length === 4) {
        for (let c = 0; c < 8; ++c) {
          if (((c >> a) & 1) !== side || !inside(c)) continue;
          const inc = faceEdges.filter((e) => EDGE_LOW[e] === c || (EDGE_LOW[e] | (1 << EDGE_AXIS[e])) === c);
          segs.push([inc[0], inc[1], c]);
        }
      }
      for (let [e0, e1, ref] of segs) {
        // Oriented so that the loops run counter-clockwise seen from outside.
        const p = edgeMid(e0);
        const s = dot(cross(sub(edgeMid(e1), p), normal), sub(corner(ref), p));
        if ((s > 0) !== inside(ref)) [e0, e1] = [e1, e0];
        if (next[e0] !== -1) throw new Error(`marching cubes: case ${index} has two segments from edge ${e0}`);
        next[e0] = e1;
      }
    }
  }
  const edges = [];
  const used = new Uint8Array(12);
  for (let start = 0; start < 12; ++start) {
    if (next[start] === -1 || used[start]) continue;
    const loop = [];
    for (let e = start; !used[e]; e = next[e]) {
      used[e] = 1;
      loop.push(e);
    }
    const n = loop.length;
    const mid = loop.map(edgeMid);
    let area = [0, 0, 0];
    for (let k = 1; k + 1 < n; ++k) {
      const t = cross(sub(mid[k], mid[0]), sub(mid[k + 1], mid[0]));
      area = [f(area[0] + t[0]), f(area[1] + t[1]), f(area[2] + t[2])];
    }
    const areaNorm = norm(area);
    let best = 0, bestScore = -Infinity;
    for (let st = 0; st < n; ++st) {
      let score = Infinity;
      for (let k = 1; k + 1 < n; ++k) {
        const nk = cross(sub(mid[(st + k) % n], mid[st]), sub(mid[(st + k + 1) % n], mid[st]));
        score = Math.min(score, f(dot(nk, area) / f(f(norm(nk) * areaNorm) + f(1e-12))));
      }
      if (score > f(bestScore + f(1e-6))) {
        bestScore = score;
        best = st;
      }
    }
    for (let k = 1; k + 1 < n; ++k) edges.push(loop[best], loop[(best + k) % n], loop[(best + k + 1) % n]);
  }
  if (edges.length > 3 * MC_MAX_TRIANGLES) throw new Error(`marching cubes: case ${index} has too many triangles`);
  return Uint8Array.from(edges);
}

// mcCases()[i]: the edges of case i's triangles, three per triangle. Built
// on first use (tens of ms while the code is cold), so that a page playing
// G1 never pays for it.
let cases = null;
export function mcCases() {
  if (!cases) cases = Array.from({ length: 256 }, (_, i) => buildCase(i));
  return cases;
}
