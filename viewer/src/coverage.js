// What is still unscanned: how far each point of a surface is from the nearest part of a slice
// plane that saw it (inside the slice's field of view), in mm. Computed here, in the page, from
// the slice messages: the stream already carries every slice, the work is done only while
// someone looks at this colouring, and it never takes time from the scan's reconstruction.
// No three.js here, so that node's test runner checks it as it is.

// How far a simplified sector outline may stray from the slice's own (mm): a convex probe's
// sector arrives with hundreds of points on its arc, and the distances need a tenth of them.
export const kOutlineToleranceMm = 0.25;

// Douglas–Peucker on a closed ring of [a, b] points: the points that keep every dropped one
// within `tolerance` of the simplified ring.
function simplifyRing(ring, tolerance) {
  if (ring.length <= 8) return ring;
  const keep = new Uint8Array(ring.length);
  const toleranceSq = tolerance * tolerance;
  const split = (first, last) => {
    const [ax, ay] = ring[first];
    const [bx, by] = ring[last % ring.length];
    const ex = bx - ax;
    const ey = by - ay;
    const lengthSq = ex * ex + ey * ey;
    let worst = -1;
    let worstSq = toleranceSq;
    for (let i = first + 1; i < last; ++i) {
      const [px, py] = ring[i];
      const t = lengthSq > 0 ? Math.max(0, Math.min(1, ((px - ax) * ex + (py - ay) * ey) / lengthSq)) : 0;
      const dSq = (ax + t * ex - px) ** 2 + (ay + t * ey - py) ** 2;
      if (dSq > worstSq) {
        worstSq = dSq;
        worst = i;
      }
    }
    if (worst < 0) return;
    keep[worst] = 1;
    split(first, worst);
    split(worst, last);
  };
  // Closed: split at the point farthest from the first, then each half.
  let far = 1;
  for (let i = 1; i < ring.length; ++i)
    if ((ring[i][0] - ring[0][0]) ** 2 + (ring[i][1] - ring[0][1]) ** 2 >
        (ring[far][0] - ring[0][0]) ** 2 + (ring[far][1] - ring[0][1]) ** 2)
      far = i;
  keep[0] = keep[far] = 1;
  split(0, far);
  split(far, ring.length);
  return ring.filter((_, i) => keep[i]);
}

/**
 * A slice as the distance needs it: its plane and the polygon of the plane it saw.
 * @param {{plane: {origin: number[], u: number[], v: number[]}, fov: number[][]|null}} slice a
 *   decoded slice message (decode.js); `fov` null: the slice saw its whole plane (slices.md)
 * @returns {{origin: number[], u: number[], v: number[], n: number[], ring: Float64Array|null,
 *   box: number[]|null}} `n` the unit normal u × v, `ring` the fov's [a, b] points flattened
 *   (simplified to kOutlineToleranceMm), `box` its [a0, a1, b0, b1]
 */
export function slicePatch(slice) {
  const { origin, u, v } = slice.plane;
  const n = [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]];
  const length = Math.hypot(n[0], n[1], n[2]) || 1;
  const ring = slice.fov ? simplifyRing(slice.fov, kOutlineToleranceMm) : null;
  const as = ring ? ring.map((p) => p[0]) : [];
  const bs = ring ? ring.map((p) => p[1]) : [];
  return {
    origin, u, v, n: n.map((x) => x / length),
    ring: ring ? Float64Array.from(ring.flat()) : null,
    box: ring ? [Math.min(...as), Math.max(...as), Math.min(...bs), Math.max(...bs)] : null,
  };
}

// Whether (a, b) is inside the ring (even-odd: fov rings are simple) and, when it is not, its
// squared distance to the ring's edges.
function ringDistanceSq(ring, a, b) {
  let inside = false;
  let best = Infinity;
  const count = ring.length / 2;
  for (let i = 0, j = count - 1; i < count; j = i++) {
    const ax = ring[2 * j];
    const ay = ring[2 * j + 1];
    const bx = ring[2 * i];
    const by = ring[2 * i + 1];
    if ((by > b) !== (ay > b) && a < ((ax - bx) * (b - by)) / (ay - by) + bx) inside = !inside;
    const ex = bx - ax;
    const ey = by - ay;
    const lengthSq = ex * ex + ey * ey;
    const t = lengthSq > 0 ? Math.max(0, Math.min(1, ((a - ax) * ex + (b - ay) * ey) / lengthSq)) : 0;
    const dx = ax + t * ex - a;
    const dy = ay + t * ey - b;
    best = Math.min(best, dx * dx + dy * dy);
  }
  return inside ? 0 : best;
}

/**
 * The distance (mm) from every position to the nearest point that a slice saw: the part of its
 * plane inside its field of view. A point on a slice inside its sector is 0; a point beside the
 * sector counts the in-plane distance to the sector too (to within kOutlineToleranceMm).
 * @param {Float32Array} positions x y z interleaved, mm
 * @param {ReturnType<typeof slicePatch>[]} patches
 * @param {number} [limitMm] distances are needed only up to this (the colour scale's end): a
 *   point farther from every slice gets limitMm, and far planes cost one dot product
 * @returns {Float32Array} one distance per position; limitMm (default Infinity) without slices
 */
export function distanceToSlices(positions, patches, limitMm = Infinity) {
  const count = positions.length / 3;
  const result = new Float32Array(count);
  // The planes flat (origin, n, u, v: 12 numbers each) for a tight inner loop.
  const planes = new Float64Array(12 * patches.length);
  patches.forEach((p, k) => planes.set([...p.origin, ...p.n, ...p.u, ...p.v], 12 * k));
  const rings = patches.map((p) => p.ring);
  const boxes = patches.map((p) => p.box);
  const limitSq = limitMm * limitMm;
  // Neighbouring vertices are mostly nearest to the same slice: starting each vertex's search at
  // the previous one's nearest makes the bound tight at once, so most planes are passed over
  // after one dot product.
  let start = 0;
  for (let i = 0; i < count; ++i) {
    const x = positions[3 * i];
    const y = positions[3 * i + 1];
    const z = positions[3 * i + 2];
    let bestSq = limitSq;
    let nearest = start;
    for (let step = 0; step < patches.length; ++step) {
      const k = (start + step) % patches.length;
      const o = 12 * k;
      const rx = x - planes[o];
      const ry = y - planes[o + 1];
      const rz = z - planes[o + 2];
      const d = rx * planes[o + 3] + ry * planes[o + 4] + rz * planes[o + 5];
      let dSq = d * d;
      // The distance to a patch is at least the distance to its plane.
      if (dSq >= bestSq) continue;
      const ring = rings[k];
      if (ring) {
        const a = rx * planes[o + 6] + ry * planes[o + 7] + rz * planes[o + 8];
        const b = rx * planes[o + 9] + ry * planes[o + 10] + rz * planes[o + 11];
        // The sector's box bounds the in-plane distance from below: a cheap second rejection.
        const box = boxes[k];
        const ea = Math.max(box[0] - a, 0, a - box[1]);
        const eb = Math.max(box[2] - b, 0, b - box[3]);
        if (dSq + ea * ea + eb * eb >= bestSq) continue;
        dSq += ringDistanceSq(ring, a, b);
        if (dSq >= bestSq) continue;
      }
      bestSq = dSq;
      nearest = k;
    }
    start = nearest;
    result[i] = Math.sqrt(bestSq);
  }
  return result;
}

// The colour ramp: scanned (0 mm) green, half the scale yellow, the scale and beyond red.
const kRamp = [[0.18, 0.75, 0.36], [0.98, 0.82, 0.2], [0.89, 0.16, 0.18]];

/**
 * The colour of a distance on a scale of `maxMm`.
 * @returns {number[]} [r, g, b], sRGB, 0..1 (as CSS shows them; the scene converts to linear)
 */
export function distanceColor(distanceMm, maxMm) {
  const t = Math.max(0, Math.min(1, distanceMm / maxMm)) * 2;
  const k = Math.min(1, Math.floor(t));
  const f = t - k;
  return kRamp[k].map((c, i) => c + (kRamp[k + 1][i] - c) * f);
}

/** The ramp as a CSS gradient, for the scale bar. */
export function rampCss() {
  const css = (c) => 'rgb(' + c.map((x) => Math.round(255 * x)).join(',') + ')';
  return 'linear-gradient(to right, ' + kRamp.map(css).join(', ') + ')';
}
