// The mean-value field of every label at a batch of points, each in its arrangement cell
// (recon/src/cell_field.cpp, CellField::evaluate_in), in OpenCL C with double precision.
//
// Every function below repeats the operations of its CPU counterpart in the same order, with no
// contraction into fused multiply-adds (FP_CONTRACT OFF) and the sums split into the same four
// lanes as the CPU's AVX2 code: IEEE double arithmetic then gives the CPU's values to the bit on
// any conforming device (the tests allow 1e-9). The CPU counterparts:
//   fast_atan2               recon/src/atan2.hpp
//   edge_term, plain_sum     mean_value.cpp (edge_terms_avx2, projected_angle_plain_avx2)
//   chain_tree_plain         chain_tree.cpp (projected_angle_tree_plain, region_term)
//   triangle_weights4        mean_value.cpp (triangle_weights4_avx2, triangle_weights)
//   triangle_tree            triangle_tree.cpp (add_triangle_weights_tree, kernel_coefficients)
// Points the CPU must take (on a face, or a non-finite value to report) get a status != 0.
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
#pragma OPENCL FP_CONTRACT OFF

#define MAX_FUNCTIONS 16
#define TREE_ORDER 12
#define MOMENT_PAIRS 49  // triangle_moment_index(TREE_ORDER + 1, 0)
#define MAX_K 7          // TREE_ORDER / 2 + 1
#define SPLIT_BELOW 1e-2
#define SPLIT_HEIGHT_RATIO 1e-2
#define CHAIN_OPENING 0.2
#define TRIANGLE_OPENING 0.35
#define EDGE_BATCH 64

// Layouts of the records (recon/src/device_field.cpp packs them).
#define FACE_INTS 8  // frame, polygon begin, count, parts begin, count, unknown begin, count, tree
#define PART_INTS 5  // material, begin, count, tree root, tree count
#define CHAIN_DOUBLES 18  // centre x y, radius^2, area, m1 x y, m2 xx xy yy, m3[4], m4[5]
#define CHAIN_INTS 4      // first, last, left, right
#define TNODE_DOUBLES 3   // centre x y, radius^2
#define TNODE_INTS 4      // first, last, left, right (relative to the face)
#define TFACE_INTS 4      // triangle begin, count, tree root (global, -1: none), moments node base

// ---- atan2 (Cephes, as recon/src/atan2.hpp) ----
__constant double kAtanP[5] = {-8.750608600031904122785e-01, -1.615753718733365076637e+01,
                               -7.500855792314704667340e+01, -1.228866684490136173410e+02,
                               -6.485021904942025371773e+01};
__constant double kAtanQ[5] = {2.485846490142306297962e+01, 1.650270098316988542046e+02,
                               4.328810604912902668951e+02, 4.853903996359136964868e+02,
                               1.945506571482613964425e+02};

double atan_small(double x) {
  const double z = x * x;
  const double p = (((kAtanP[0] * z + kAtanP[1]) * z + kAtanP[2]) * z + kAtanP[3]) * z + kAtanP[4];
  const double q =
      ((((z + kAtanQ[0]) * z + kAtanQ[1]) * z + kAtanQ[2]) * z + kAtanQ[3]) * z + kAtanQ[4];
  return x + x * (z * p / q);
}

double atan_unit(double t) {
  if (t <= 0.66) return atan_small(t);
  return 0.78539816339744830962 + (atan_small((t - 1.0) / (t + 1.0)) + 3.061616997868382943065e-17);
}

double fast_atan2(double y, double x) {
  const double ay = fabs(y), ax = fabs(x);
  double angle;
  if (ay <= ax)
    angle = ax > 0.0 ? atan_unit(ay / ax) : 0.0;
  else
    angle = 1.57079632679489661923 - atan_unit(ax / ay);
  if (signbit(x)) angle = 3.14159265358979323846 - angle;
  return copysign(angle, y);
}

// ---- edge terms ----
// edge_angle (mean_value.hpp): the angle and q L of the edge a -> b relative to the foot.
double edge_angle(double2 a, double2 b, double2 d, double cross, double length_sq, double h2,
                  double* q_length) {
  const double big_q = cross * cross + h2 * length_sq;
  *q_length = sqrt(big_q);
  const double a_dot_d = a.x * d.x + a.y * d.y;
  const double b_dot_d = b.x * d.x + b.y * d.y;
  return fast_atan2(*q_length * length_sq, big_q + a_dot_d * b_dot_d);
}

// edge_projected_angle (mean_value.hpp).
double edge_term(double2 a, double2 b, double h2) {
  const double2 d = b - a;
  const double length_sq = d.x * d.x + d.y * d.y;
  const double cross = a.x * b.y - a.y * b.x;
  if (cross == 0.0 || !(length_sq > 0.0)) return 0.0;
  double q_length;
  const double angle = edge_angle(a, b, d, cross, length_sq, h2, &q_length);
  return (cross / q_length) * angle;
}

// !(x > 0) lane by lane (true for NaN: _CMP_NGT_UQ).
long4 isnotgreater4(double4 x) { return ~isgreater(x, (double4)(0.0)); }

// ---- four edges at once (the lanes of mean_value.cpp's AVX2 code, as double4) ----
// atan_small and fast_atan2 for y >= 0, lane by lane, both branches computed and the scalar
// code's one selected (atan2_nonnegative_y_avx2): every lane equals fast_atan2 to the bit.
double4 atan_small4(double4 x) {
  const double4 z = x * x;
  double4 p = (double4)(kAtanP[0]);
  for (int k = 1; k < 5; ++k) p = p * z + kAtanP[k];
  double4 q = z + kAtanQ[0];
  for (int k = 1; k < 5; ++k) q = q * z + kAtanQ[k];
  return x + x * (z * p / q);
}

double4 atan2_nonnegative_y4(double4 y, double4 x) {
  const double4 ax = fabs(x);
  const long4 steep = isgreater(y, ax);
  const double4 numerator = select(y, ax, steep);
  const double4 denominator = select(ax, y, steep);
  const double4 t =
      select(numerator / denominator, (double4)(0.0), isequal(denominator, (double4)(0.0)));
  const long4 large = isgreater(t, (double4)(0.66));
  const double4 small_angle = atan_small4(select(t, (t - 1.0) / (t + 1.0), large));
  const double4 unit_angle = select(
      small_angle, 0.78539816339744830962 + (small_angle + 3.061616997868382943065e-17), large);
  const double4 angle = select(unit_angle, 1.57079632679489661923 - unit_angle, steep);
  return select(angle, 3.14159265358979323846 - angle, signbit(x));
}

// edge_term of four edges (0 in the lanes where it exits early), edge_terms_avx2.
double4 edge_term4(double4 ax, double4 ay, double4 bx, double4 by, double h2) {
  const double4 dx = bx - ax, dy = by - ay;
  const double4 length_sq = dx * dx + dy * dy;
  const double4 cross = ax * by - ay * bx;
  const double4 big_q = cross * cross + h2 * length_sq;
  const double4 q_length = sqrt(big_q);
  const double4 a_dot_d = ax * dx + ay * dy;
  const double4 b_dot_d = bx * dx + by * dy;
  const double4 angle = atan2_nonnegative_y4(q_length * length_sq, big_q + a_dot_d * b_dot_d);
  const double4 term = (cross / q_length) * angle;
  const long4 skip = isequal(cross, (double4)(0.0)) | isnotgreater4(length_sq);
  return select(term, (double4)(0.0), skip);
}

// projected_angle_plain: edge k (from point k - 1 to point k) in lane k mod 4, the lanes summed
// pairwise (projected_angle_plain_avx2, whose padding edges past the last are zero-length).
double plain_sum(__global const double2* points, uint count, double2 foot, double height) {
  const double h2 = height * height;
  double4 sums = (double4)(0.0);
  double2 a = points[count - 1] - foot;
  for (uint k = 0; k < count; k += 4) {
    double2 p[5];
    p[0] = a;
    for (uint j = 1; j <= 4; ++j) p[j] = k + j <= count ? points[k + j - 1] - foot : p[j - 1];
    sums += edge_term4(
        (double4)(p[0].x, p[1].x, p[2].x, p[3].x), (double4)(p[0].y, p[1].y, p[2].y, p[3].y),
        (double4)(p[1].x, p[2].x, p[3].x, p[4].x), (double4)(p[1].y, p[2].y, p[3].y, p[4].y), h2);
    a = p[4];
  }
  return (sums.s0 + sums.s1) + (sums.s2 + sums.s3);
}

// ---- chain trees (far field of long rings) ----
double region_term(__global const double* node, double dx, double dy, double s, double h2) {
  const double inv_s = 1.0 / s;
  const double dx2 = dx * dx, dy2 = dy * dy, dxy = dx * dy;
  const double area = node[3], m1x = node[4], m1y = node[5];
  const double m2xx = node[6], m2xy = node[7], m2yy = node[8];
  __global const double* m3 = node + 9;
  __global const double* m4 = node + 13;
  const double d_z = dx * m1x + dy * m1y;
  const double d_z2 = dx2 * m2xx + 2.0 * dxy * m2xy + dy2 * m2yy;
  const double z2 = m2xx + m2yy;
  const double d_z_z2 = dx * (m3[0] + m3[2]) + dy * (m3[1] + m3[3]);
  const double d_z3 =
      dx * dx2 * m3[0] + 3.0 * dx2 * dy * m3[1] + 3.0 * dx * dy2 * m3[2] + dy * dy2 * m3[3];
  const double z4 = m4[0] + 2.0 * m4[2] + m4[4];
  const double d_z2_z2 =
      dx2 * (m4[0] + m4[2]) + 2.0 * dxy * (m4[1] + m4[3]) + dy2 * (m4[2] + m4[4]);
  const double d_z4 = dx2 * dx2 * m4[0] + 4.0 * dx2 * dxy * m4[1] + 6.0 * dx2 * dy2 * m4[2] +
                      4.0 * dxy * dy2 * m4[3] + dy2 * dy2 * m4[4];
  const double series =
      area + inv_s * (-4.0 * d_z - 2.0 * z2 +
                      inv_s * (12.0 * d_z2 + 12.0 * d_z_z2 + 3.0 * z4 +
                               inv_s * (-32.0 * d_z3 - 48.0 * d_z2_z2 + inv_s * 80.0 * d_z4)));
  return 2.0 * h2 * inv_s * inv_s * series;
}

// The edges summed exactly, in batches of EDGE_BATCH whose edge i goes to lane i mod 4
// (edge_projected_angle_sum_avx2; a batch's lanes are summed pairwise into `edges`, its last
// group padded with zero edges). Edges are gathered four at a time and computed as one double4.
typedef struct {
  double4 lanes;
  double ax[4], ay[4], bx[4], by[4];
  uint pending;  // edges in the batch
  double edges;
} EdgeBatch;

void batch_group(EdgeBatch* batch, double h2) {
  batch->lanes += edge_term4(vload4(0, batch->ax), vload4(0, batch->ay), vload4(0, batch->bx),
                             vload4(0, batch->by), h2);
}

void batch_push(EdgeBatch* batch, double2 a, double2 b, double h2) {
  const uint slot = batch->pending & 3;
  batch->ax[slot] = a.x;
  batch->ay[slot] = a.y;
  batch->bx[slot] = b.x;
  batch->by[slot] = b.y;
  ++batch->pending;
  if ((batch->pending & 3) == 0) batch_group(batch, h2);
  if (batch->pending == EDGE_BATCH) {
    batch->edges += (batch->lanes.s0 + batch->lanes.s1) + (batch->lanes.s2 + batch->lanes.s3);
    batch->lanes = (double4)(0.0);
    batch->pending = 0;
  }
}

void batch_finish(EdgeBatch* batch, double h2) {
  if (batch->pending == 0) return;
  for (uint slot = batch->pending & 3; slot != 0 && slot < 4; ++slot)
    batch->ax[slot] = batch->ay[slot] = batch->bx[slot] = batch->by[slot] = 0.0;
  if ((batch->pending & 3) != 0) batch_group(batch, h2);
  batch->edges += (batch->lanes.s0 + batch->lanes.s1) + (batch->lanes.s2 + batch->lanes.s3);
}

double chain_tree_plain(__global const double2* points, uint count, __global const double* chain_d,
                        __global const int* chain_i, uint root, double2 foot, double height) {
  if (count < 2 || !(height > 0.0)) return 0.0;
  const double h2 = height * height;
  const double opening_sq = CHAIN_OPENING * CHAIN_OPENING;
  EdgeBatch batch;
  batch.lanes = (double4)(0.0);
  batch.pending = 0;
  batch.edges = 0.0;
  double regions = 0.0;
  uint stack[64];
  int top = 0;
  stack[top++] = root;
  while (top > 0) {
    const uint n = stack[--top];
    __global const double* node = chain_d + (size_t)n * CHAIN_DOUBLES;
    __global const int* links = chain_i + (size_t)n * CHAIN_INTS;
    const double dx = node[0] - foot.x, dy = node[1] - foot.y;
    const double s = (dx * dx + dy * dy) + h2;
    const uint first = (uint)links[0], last = (uint)links[1];
    if (node[2] < opening_sq * s) {
      regions += region_term(node, dx, dy, s, h2);
      batch_push(&batch, points[first % count] - foot, points[last % count] - foot, h2);
      continue;
    }
    if (links[2] < 0) {
      double2 a = points[first % count] - foot;
      for (uint i = first; i < last; ++i) {
        const double2 b = points[(i + 1) % count] - foot;
        batch_push(&batch, a, b, h2);
        a = b;
      }
      continue;
    }
    stack[top++] = (uint)links[3];
    stack[top++] = (uint)links[2];
  }
  batch_finish(&batch, h2);
  return batch.edges + regions;
}

// CellField::part_angle.
double part_angle(__global const int* part, __global const double2* points,
                  __global const double* chain_d, __global const int* chain_i, double2 foot,
                  double height) {
  const uint begin = (uint)part[1], count = (uint)part[2], tree_count = (uint)part[4];
  if (tree_count == 0) {
    if (count < 2 || !(height > 0.0)) return 0.0;
    return plain_sum(points + begin, count, foot, height);
  }
  return chain_tree_plain(points + begin, count, chain_d, chain_i, (uint)part[3], foot, height);
}

// ---- triangle weights (Ju et al. by Stokes, mean_value.cpp) ----
// edge_projected_angle_split; false when the edge's line passes through the foot.
bool edge_split(double2 a, double2 b, double h2, double* planar, double* remainder) {
  const double2 d = b - a;
  const double length_sq = d.x * d.x + d.y * d.y;
  if (!(length_sq > 0.0)) return true;
  const double length = sqrt(length_sq);
  const double c = (a.x * b.y - a.y * b.x) / length;
  if (c == 0.0) return false;
  const double s_a = (a.x * d.x + a.y * d.y) / length, s_b = (b.x * d.x + b.y * d.y) / length;
  const double abs_c = fabs(c), sign = c > 0.0 ? 1.0 : -1.0;
  const double q = sqrt(c * c + h2);
  const double phi_c = fast_atan2(abs_c * length, c * c + s_a * s_b);
  const double phi_q = fast_atan2(q * length, q * q + s_a * s_b);
  const double shrink = h2 / (q + abs_c);
  const double phi_difference = fast_atan2(-s_b * shrink, q * abs_c + s_b * s_b) -
                                fast_atan2(-s_a * shrink, q * abs_c + s_a * s_a);
  *planar += sign * phi_c;
  *remainder += sign * (-shrink / q * phi_q + phi_difference);
  return true;
}

// projected_angle_split of a triangle's ring.
double triangle_split(const double2* ring, double2 foot, double height, double plain) {
  const double h2 = height * height;
  double planar = 0.0, remainder = 0.0;
  double2 a = ring[2] - foot;
  for (int i = 0; i < 3; ++i) {
    const double2 b = ring[i] - foot;
    if (!edge_split(a, b, h2, &planar, &remainder)) return plain;
    a = b;
  }
  const double two_pi = 6.283185307179586476925286766559;
  return round(planar / two_pi) != 0.0 ? plain : remainder;
}

// triangle_weights of `count` (1 to 4) triangles, their edge angles four at a time in double4
// lanes (triangle_weights4_avx2; lanes past `count` repeat the last triangle), the rest lane by
// lane: every weight is triangle_weights' to the bit. ok[t] as triangle_weights' result.
void triangle_weights4(__global const double* triangles, uint count, double2 foot, double height,
                       double weights[4][3], bool ok[4]) {
  double2 corners[4][3], ring[4][3];
  double twice_area[4], longest_sq[4];
  bool valid[4];
  for (uint t = 0; t < 4; ++t) {
    __global const double* c = triangles + (size_t)min(t, count - 1) * 6;
    corners[t][0] = (double2)(c[0], c[1]);
    corners[t][1] = (double2)(c[2], c[3]);
    corners[t][2] = (double2)(c[4], c[5]);
    const double2 a = corners[t][0], b = corners[t][1], cc = corners[t][2];
    const double2 ab = b - a, ac = cc - a, bc = cc - b, ca = a - cc, fa = foot - a;
    twice_area[t] = ab.x * ac.y - ab.y * ac.x;
    longest_sq[t] =
        fmax(fmax(ab.x * ab.x + ab.y * ab.y, bc.x * bc.x + bc.y * bc.y), ca.x * ca.x + ca.y * ca.y);
    const double reach_sq = (fa.x * fa.x + fa.y * fa.y) + height * height;
    valid[t] = fabs(twice_area[t]) > 1e-12 * fmax(longest_sq[t], 1e-12 * reach_sq) && height > 0.0;
    ring[t][0] = a;
    ring[t][1] = twice_area[t] > 0 ? b : cc;
    ring[t][2] = twice_area[t] > 0 ? cc : b;
  }
  const double h2 = height * height;
  double4 sum = (double4)(0.0), mx = (double4)(0.0), my = (double4)(0.0);
  for (int k = 0; k < 3; ++k) {
    const int k1 = (k + 1) % 3;
    const double4 px = (double4)(ring[0][k].x, ring[1][k].x, ring[2][k].x, ring[3][k].x) - foot.x;
    const double4 py = (double4)(ring[0][k].y, ring[1][k].y, ring[2][k].y, ring[3][k].y) - foot.y;
    const double4 qx =
        (double4)(ring[0][k1].x, ring[1][k1].x, ring[2][k1].x, ring[3][k1].x) - foot.x;
    const double4 qy =
        (double4)(ring[0][k1].y, ring[1][k1].y, ring[2][k1].y, ring[3][k1].y) - foot.y;
    const double4 dx = qx - px, dy = qy - py;
    const double4 length_sq = dx * dx + dy * dy;
    const double4 cross = px * qy - py * qx;
    const double4 big_q = cross * cross + h2 * length_sq;
    const double4 q_length = sqrt(big_q);
    const double4 a_dot_d = px * dx + py * dy;
    const double4 b_dot_d = qx * dx + qy * dy;
    const double4 angle = atan2_nonnegative_y4(q_length * length_sq, big_q + a_dot_d * b_dot_d);
    const double4 angle_over_q_length = angle / q_length;
    sum += cross * angle_over_q_length;
    const double4 scale = (-0.5 * height) * angle_over_q_length;
    mx += scale * dy;
    my += scale * -dx;
  }
  const double lanes_sum[4] = {sum.s0, sum.s1, sum.s2, sum.s3};
  const double lanes_mx[4] = {mx.s0, mx.s1, mx.s2, mx.s3};
  const double lanes_my[4] = {my.s0, my.s1, my.s2, my.s3};
  for (uint t = 0; t < count; ++t) {
    ok[t] = false;
    if (!valid[t]) continue;
    double projected = lanes_sum[t];
    if (fabs(projected) < SPLIT_BELOW &&
        height * height < (SPLIT_HEIGHT_RATIO * SPLIT_HEIGHT_RATIO) * longest_sq[t])
      projected = triangle_split(ring[t], foot, height, projected);
    const double inverse_area = 1.0 / twice_area[t], projected_over_height = projected / height;
    for (int i = 0; i < 3; ++i) {
      const double2 p1 = corners[t][(i + 1) % 3], p2 = corners[t][(i + 2) % 3];
      const double2 e = p2 - p1;
      const double gx = -e.y * inverse_area, gy = e.x * inverse_area;
      const double2 f = foot - p1;
      const double lambda_at_foot = gx * f.x + gy * f.y;
      weights[t][i] =
          lambda_at_foot * projected_over_height + 2.0 * (gx * lanes_mx[t] + gy * lanes_my[t]);
    }
    ok[t] = isfinite(weights[t][0]) && isfinite(weights[t][1]) && isfinite(weights[t][2]);
  }
}

// add_exact (triangle_tree.cpp): triangles [first, last) of a face in their order, four at a
// time (triangle_weights4).
void add_exact(__global const double* triangles, __global const double* values, uint first,
               uint last, int fc, double2 foot, double height, double* w) {
  for (uint block = first; block < last; block += 4) {
    const uint count = min(4u, last - block);
    double weights[4][3];
    bool ok[4];
    triangle_weights4(triangles + (size_t)block * 6, count, foot, height, weights, ok);
    for (uint t = 0; t < count; ++t) {
      if (!ok[t]) continue;
      __global const double* v = values + (size_t)(block + t) * 3 * fc;
      for (int k = 0; k < 3; ++k) {
        const double weight = weights[t][k];
        for (int l = 0; l < fc; ++l) w[l] += 0.5 * weight * (1.0 + v[k * fc + l]);
      }
    }
  }
}

uint moment_index(int a, int b) {
  uint index = 0;
  for (int n = 0; n < a + b; ++n) index += (uint)(n / 2 + 1);
  return index + (uint)b;
}

// kernel_coefficients (triangle_tree.cpp); `pairs` holds (a, b) per moment pair and `table`
// the coefficients F(a, b, k) (MAX_K per pair).
void kernel_coefficients(double dx, double dy, double s, int degree, __constant const int* pairs,
                         __constant const double* table, double* out) {
  const double inv_s = 1.0 / s;
  const double wr = dx * inv_s, wi = -dy * inv_s;
  const double ratio = (dx * dx + dy * dy) * inv_s;
  double power_re[TREE_ORDER + 1], power_im[TREE_ORDER + 1], inv_s_power[TREE_ORDER / 2 + 1];
  power_re[0] = 1.0;
  power_im[0] = 0.0;
  for (int m = 1; m <= degree; ++m) {
    power_re[m] = power_re[m - 1] * wr - power_im[m - 1] * wi;
    power_im[m] = power_re[m - 1] * wi + power_im[m - 1] * wr;
  }
  inv_s_power[0] = 1.0;
  for (int m = 1; m <= degree / 2; ++m) inv_s_power[m] = inv_s_power[m - 1] * inv_s;
  const uint count = moment_index(degree + 1, 0);
  for (uint p = 0; p < count; ++p) {
    const int a = pairs[2 * p], b = pairs[2 * p + 1];
    double g = table[p * MAX_K];
    for (int k = 1; k <= b; ++k) g = g * ratio + table[p * MAX_K + k];
    const double factor = (a > b ? 2.0 : 1.0) * g * inv_s_power[b];
    out[2 * p] = factor * power_re[a - b];
    out[2 * p + 1] = -factor * power_im[a - b];
  }
}

// add_triangle_weights_tree (triangle_tree.cpp) of one face's tree.
void triangle_tree(__global const double* triangles, __global const double* values, int fc,
                   __global const double* tnode_d, __global const int* tnode_i,
                   __global const double* moments, uint root, uint moments_base, double2 foot,
                   double height, __constant const int* pairs, __constant const double* table,
                   __constant const double* truncation, double* w) {
  if (!(height > 0.0)) return;
  const size_t moment_count = 2 * MOMENT_PAIRS;
  const size_t stride = (size_t)fc * moment_count;
  const double h2 = height * height;
  const double opening_sq = TRIANGLE_OPENING * TRIANGLE_OPENING;
  // root: the face's root node in the global arrays; children are relative to it.
  uint stack[64];
  int top = 0;
  stack[top++] = 0;
  double coefficients[2 * MOMENT_PAIRS];
  while (top > 0) {
    const uint node_index = stack[--top];
    __global const double* node = tnode_d + (size_t)(root + node_index) * TNODE_DOUBLES;
    __global const int* links = tnode_i + (size_t)(root + node_index) * TNODE_INTS;
    const double dx = node[0] - foot.x, dy = node[1] - foot.y;
    const double s = (dx * dx + dy * dy) + h2;
    if (node[2] < opening_sq * s) {
      const double scale = 2.0 * height / (s * s);
      __global const double* m = moments + (size_t)(moments_base + node_index) * stride;
      int degree = 1;
      while (degree < TREE_ORDER && node[2] > truncation[degree] * s) ++degree;
      const uint used = 2 * moment_index(degree + 1, 0);
      kernel_coefficients(dx, dy, s, degree, pairs, table, coefficients);
      for (int l = 0; l < fc; ++l) {
        __global const double* density = m + (size_t)l * moment_count;
        double s0 = 0.0, s1 = 0.0, s2 = 0.0, s3 = 0.0;
        uint k = 0;
        for (; k + 4 <= used; k += 4) {
          s0 += coefficients[k] * density[k];
          s1 += coefficients[k + 1] * density[k + 1];
          s2 += coefficients[k + 2] * density[k + 2];
          s3 += coefficients[k + 3] * density[k + 3];
        }
        if (k < used) {
          s0 += coefficients[k] * density[k];
          s1 += coefficients[k + 1] * density[k + 1];
        }
        w[l] += scale * ((s0 + s1) + (s2 + s3));
      }
      continue;
    }
    if (links[2] < 0) {
      add_exact(triangles, values, (uint)links[0], (uint)links[1], fc, foot, height, w);
      continue;
    }
    stack[top++] = (uint)links[3];
    stack[top++] = (uint)links[2];
  }
}

// ---- the field at one point (CellField::evaluate_in) ----
// point_faces[n]: (first, count) of the point's cell's faces in face_list. status[n]: 0 done,
// 1 on a face (the CPU evaluates it), 2 a non-finite value (the CPU reports it).
__kernel void evaluate_field(
    const uint point_count, const int fc, const double on_face_height,
    __global const double* positions,  // 3 per point
    __global const uint* point_faces,  // 2 per point
    __global const int* face_list,
    __global const double* frames,  // 12 per frame: origin, u, v, unit normal
    __global const int* faces,      // FACE_INTS per face
    __global const int* parts,      // PART_INTS per part
    __global const double2* points, __global const double* chain_d, __global const int* chain_i,
    __global const int* triangle_faces,  // TFACE_INTS per face
    __global const double* triangles,    // 6 per triangle
    __global const double* corner_values, __global const double* tnode_d,
    __global const int* tnode_i, __global const double* moments, __constant const int* pairs,
    __constant const double* table, __constant const double* truncation, __global double* out,
    __global int* status) {
  const uint n = get_global_id(0);
  if (n >= point_count) return;
  const double px = positions[3 * n], py = positions[3 * n + 1], pz = positions[3 * n + 2];
  double w[MAX_FUNCTIONS], face_w[MAX_FUNCTIONS];
  for (int l = 0; l < fc; ++l) w[l] = 0.0;
  double total = 0.0, known_materials = 0.0, unknown_total = 0.0;
  const uint face_first = point_faces[2 * n], face_count = point_faces[2 * n + 1];
  for (uint i = 0; i < face_count; ++i) {
    const int f = face_list[face_first + i];
    __global const int* face = faces + (size_t)f * FACE_INTS;
    __global const double* frame = frames + (size_t)face[0] * 12;
    const double dx = px - frame[0], dy = py - frame[1], dz = pz - frame[2];
    const double height = fabs((dx * frame[9] + dy * frame[10]) + dz * frame[11]);
    const double2 foot = (double2)((dx * frame[3] + dy * frame[4]) + dz * frame[5],
                                   (dx * frame[6] + dy * frame[7]) + dz * frame[8]);
    if (height <= on_face_height) {
      status[n] = 1;
      return;
    }
    const double inv_height = 1.0 / height;
    total += plain_sum(points + face[1], (uint)face[2], foot, height) * inv_height;
    for (int k = 0; k < face[4]; ++k) {
      __global const int* part = parts + (size_t)(face[3] + k) * PART_INTS;
      const double weight = part_angle(part, points, chain_d, chain_i, foot, height) * inv_height;
      w[part[0]] += weight;
      known_materials += weight;
    }
    __global const int* tface = triangle_faces + (size_t)f * TFACE_INTS;
    const uint triangle_begin = (uint)tface[0], triangle_count = (uint)tface[1];
    if (triangle_count == 0) continue;
    for (int l = 0; l < fc; ++l) face_w[l] = 0.0;
    __global const double* face_triangles = triangles + (size_t)triangle_begin * 6;
    __global const double* face_values = corner_values + (size_t)triangle_begin * 3 * fc;
    if (tface[2] >= 0) {
      triangle_tree(face_triangles, face_values, fc, tnode_d, tnode_i, moments, (uint)tface[2],
                    (uint)tface[3], foot, height, pairs, table, truncation, face_w);
    } else {
      add_exact(face_triangles, face_values, 0, triangle_count, fc, foot, height, face_w);
    }
    double face_unknown = 0.0;
    for (int l = 0; l < fc; ++l) face_unknown += face_w[l];
    if (!(face_unknown > 0.0)) continue;
    double exact_unknown = 0.0;
    for (int k = 0; k < face[6]; ++k) {
      __global const int* part = parts + (size_t)(face[5] + k) * PART_INTS;
      exact_unknown += part_angle(part, points, chain_d, chain_i, foot, height) * inv_height;
    }
    const double scale = exact_unknown / face_unknown;
    unknown_total += exact_unknown;
    for (int l = 0; l < fc; ++l) w[l] += scale * face_w[l];
  }
  __global double* values = out + (size_t)n * fc;
  int finite = 1;
  for (int l = 1; l < fc; ++l) {
    values[l] = 2.0 * w[l] / total - 1.0;
    finite &= isfinite(values[l]);
  }
  values[0] = 2.0 * (total - known_materials - unknown_total + w[0]) / total - 1.0;
  finite &= isfinite(values[0]);
  status[n] = finite ? 0 : 2;
}
