// What is still unscanned: the distance from surface points to the slices that saw them.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { distanceToSlices, distanceColor, kOutlineToleranceMm, slicePatch } from '../src/coverage.js';

// A slice in the plane z = z0 whose sector is the square [0, 10] x [0, 10] of (x, y).
function squareSlice(z0) {
  return slicePatch({
    plane: { origin: [0, 0, z0], u: [1, 0, 0], v: [0, 1, 0] },
    fov: [[0, 0], [10, 0], [10, 10], [0, 10]],
  });
}

const near = (actual, expected) => assert.ok(Math.abs(actual - expected) < 1e-5, `${actual} != ${expected}`);

test('a point on a slice inside its sector is at 0 mm, above it at its height', () => {
  const d = distanceToSlices(new Float32Array([5, 5, 0, 5, 5, 3, 5, 5, -4]), [squareSlice(0)]);
  near(d[0], 0);
  near(d[1], 3);
  near(d[2], 4);
});

test('beside the sector the in-plane distance counts too: the slice did not see there', () => {
  const d = distanceToSlices(new Float32Array([13, 5, 0, 13, 14, 0, 13, 5, 4]), [squareSlice(0)]);
  near(d[0], 3);
  near(d[1], 5);            // to the corner (10, 10): 3, 4
  near(d[2], 5);            // 3 beside, 4 above
});

test('the nearest of several slices wins, and a slice without a sector saw its whole plane', () => {
  const slices = [squareSlice(0), squareSlice(10)];
  const d = distanceToSlices(new Float32Array([5, 5, 7, 5, 5, 2]), slices);
  near(d[0], 3);
  near(d[1], 2);
  const whole = slicePatch({ plane: { origin: [0, 0, 0], u: [0, 1, 0], v: [0, 0, 1] }, fov: null });
  near(distanceToSlices(new Float32Array([-6, 500, 500]), [whole])[0], 6);
  assert.equal(distanceToSlices(new Float32Array([1, 2, 3]), [])[0], Infinity);
});

test('an oblique slice: distances do not depend on its orientation', () => {
  const c = Math.SQRT1_2;
  const tilted = slicePatch({
    plane: { origin: [0, 0, 0], u: [c, c, 0], v: [0, 0, 1] },
    fov: [[-10, -10], [10, -10], [10, 10], [-10, 10]],
  });
  // The normal is u x v = (c, -c, 0): 2 mm along it from a point inside the sector.
  const d = distanceToSlices(new Float32Array([1 * c + 2 * c, 1 * c - 2 * c, 3]), [tilted]);
  near(d[0], 2);
});

test('the colour ramp runs from green (scanned) through yellow to red at the scale', () => {
  const [r0, g0] = distanceColor(0, 10);
  assert.ok(g0 > r0);
  const far = distanceColor(10, 10);
  assert.deepEqual(distanceColor(50, 10), far);
  assert.ok(far[0] > far[1]);
  const mid = distanceColor(5, 10);
  assert.ok(mid[0] > 0.9 && mid[1] > 0.7);
});

test('a sector with hundreds of points on its arc: distances within the outline tolerance', () => {
  // A convex probe's sector: apex at (0, -20), arc of radius 120 about it, 256 points.
  const fov = [];
  for (let i = 0; i < 255; ++i) {
    const angle = -0.6 + (1.2 * i) / 254;
    fov.push([120 * Math.sin(angle), -20 + 120 * Math.cos(angle)]);
  }
  fov.push([0, -20]);
  const patch = slicePatch({ plane: { origin: [0, 0, 0], u: [1, 0, 0], v: [0, 1, 0] }, fov });
  assert.ok(patch.ring.length / 2 < 64, `${patch.ring.length / 2} points kept`);
  const points = [];
  const expected = [];
  for (let i = 0; i < 50; ++i) {
    const angle = -0.55 + (1.1 * i) / 49;
    const radius = 125 + (i % 5);  // outside the arc, in the plane: the distance is radial
    points.push(radius * Math.sin(angle), -20 + radius * Math.cos(angle), 0);
    expected.push(radius - 120);
  }
  const d = distanceToSlices(new Float32Array(points), [patch]);
  expected.forEach((e, i) => assert.ok(Math.abs(d[i] - e) <= kOutlineToleranceMm + 1e-3, `${d[i]} vs ${e}`));
  near(distanceToSlices(new Float32Array([0, 50, 0]), [patch])[0], 0);  // inside the sector
});
