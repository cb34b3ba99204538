// The fused forward camera (`fused.py` builds and loads this file): per view, the hierarchy cut, the EWA
// projection with SH colours, the 4x4 tile binning and the front-to-back composite, in one call for all
// cameras, cameras spread over threads. No gradients: the pure-torch renderer is the reference it is
// tested against, and every formula below is that renderer's, in the same float32 operation order where it
// decides membership (the cut's tests, the projection's culls), so the cut is the reference's cut exactly.
//
// Built with -ffp-contract=off: no fused multiply-adds, so a*b+c rounds as torch's elementwise ops do.
#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <numeric>
#include <thread>
#include <vector>

namespace {

constexpr int TS = 4;                      // tile side (the reference's CPU tile size)
constexpr float ALPHA_MIN = 1.0f / 255.0f;  // projection.ALPHA_THRESHOLD / rasterize.ALPHA_MIN
constexpr float ALPHA_MAX = 0.999f;
constexpr float T_EPS = 1e-4f;
constexpr float RADIUS_SIGMAS = 3.33f;
constexpr float SH_C0 = 0.28209479177387814f;
constexpr float SH_C1 = 0.4886025119029199f;
constexpr float SH_C2[5] = {1.0925484305920792f, -1.0925484305920792f, 0.31539156525252005f, -1.0925484305920792f,
                            0.5462742152960396f};
constexpr float SH_C3[7] = {-0.5900435899266435f, 2.890611442640554f, -0.4570457994644658f, 0.3731763325901154f,
                            -0.4570457994644658f, 1.445305721320277f, -0.5900435899266435f};

}  // namespace

extern "C" {

// Everything one call reads and writes; mirrored field by field by `fused._Args` (ctypes).
struct WlArgs {
  // the scene: node ids 0..N-1 are leaves, N..N+I-1 merged nodes (I = 0 for plain Gaussians)
  int64_t N, I, K;  // K: SH coefficients per channel stored (leaf_rest holds K-1)
  int32_t sh_degree, use_cut;
  // one 64-byte record per node (what the cut and the projection read, one cache line): centre x y z,
  // bounding-sphere radius, covariance xx xy xz yy yz zz (off-diagonals symmetrised as packed._sym6),
  // activated opacity, SH DC r g b, the node's id (int32 bits), the cut's size multiplier (lod_scale). Records are stored by slot: a
  // hierarchy's in the order of its child lists (the root last), so that the children of interior node id j
  // are the slots child_ptr[j - N] .. child_ptr[j - N + 1] - 1, side by side; plain Gaussians' slot = id.
  const float* rec;        // [N + I, 16]
  const float* leaf_rest;  // [N, K-1, 3] higher SH coefficients of the leaves
  const float* node_sh;    // [I, K, 3] SH coefficients of the merged nodes
  const int64_t* child_ptr;  // [I + 1]
  const int64_t* start;      // [n_start] the slots where each view's descent starts
  int64_t n_start;
  // the cameras
  int64_t C;
  const float* table;    // [21, C] hierarchy._camera_table
  const float* viewmat;  // [C, 16] cam_from_world
  const float* Ks;       // [C, 9]
  const float* campos;   // [C, 3] camera centres (SH directions)
  const float* bg;       // [C, 3] or null (black)
  int32_t width, height, camera_model, antialiased;  // camera_model: 0 pinhole, 1 fisheye
  float target_px, near_plane, far_plane, eps2d, radius_clip;
  // per-camera extra Gaussians (overlay.CameraGaussians), appended after the camera's cut
  int64_t M;
  const float* ex_means;  // [C, M, 3]
  const float* ex_cov;    // [C, M, 9]
  const float* ex_opac;   // [C, M]
  const float* ex_rgb;    // [C, M, 3]
  // outputs, [C, H, W, ...]; null where not wanted
  float* rgb;    // [C, H, W, 3] clamped to [0, 1], background blended
  float* depth;  // [C, H, W] (depth_mode 1: sum w z; 2: sum w z / max(alpha, 1e-10))
  float* alpha;  // [C, H, W] accumulated opacity
  int32_t depth_mode, want_rgb;
  int64_t* drawn;  // [C] nodes in each camera's cut (plus its extra rows), or null
  int64_t* pairs;  // [C] Gaussians that survive projection, or null
  int32_t threads;
};

}  // extern "C"

namespace {

inline int64_t node_id(const float* rec) {
  int32_t id;
  std::memcpy(&id, rec + 14, 4);
  return id;
}

struct Splat {
  float mx, my, a, b, c, limit, lo, depth;
  float col[3];
  int rx, ry;
};

// Per camera, the reference's cut (hierarchy.GaussianHierarchy.cut): a breadth-first descent from the start
// nodes, level by level, keeping visible nodes that are leaves or project to at most target_px pixels; out:
// the kept slots, in the reference's order.
void cut_camera(const WlArgs& a, int64_t cam, std::vector<int64_t>& out, std::vector<int64_t>& frontier,
                std::vector<int64_t>& next) {
  out.clear();
  const int64_t C = a.C, N = a.N;
  float c[21];
  for (int k = 0; k < 21; ++k) c[k] = a.table[k * C + cam];
  const bool pinhole = a.camera_model == 0;
  const float near = a.near_plane, target = a.target_px;
  frontier.assign(a.start, a.start + a.n_start);
  while (!frontier.empty()) {
    next.clear();
    const size_t F = frontier.size();
    for (size_t f = 0; f < F; ++f) {
      const int64_t node = frontier[f];
      if (f + 8 < F) __builtin_prefetch(a.rec + frontier[f + 8] * 16);
      const float* rec = a.rec + node * 16;
      const float m[3] = {rec[0], rec[1], rec[2]};
      const float r = rec[3];
      float p[3];
      for (int i = 0; i < 3; ++i) p[i] = c[3 * i] * m[0] + c[3 * i + 1] * m[1] + c[3 * i + 2] * m[2] + c[9 + i];
      const float x = p[0], y = p[1], z = p[2];
      const float dist = std::sqrt(x * x + y * y + z * z);
      bool visible = z + r >= near;
      float size;
      bool close;
      if (pinhole) {
        const float coord[4] = {x, x, y, y};
        for (int i = 0; i < 4; ++i) visible = visible && (c[13 + i] * coord[i] - c[17 + i] * z) <= r;
        size = c[12] * r * dist / (std::max(z, 1e-6f) * std::max(z - r, 1e-6f));
        close = z - r <= near;
      } else {
        size = c[12] * r / std::max(dist - r, 1e-6f);
        close = dist - r <= near;
      }
      if (!visible) continue;
      const int64_t id = node_id(rec);
      const bool expand = id >= N && (close || size * rec[15] > target);
      if (!expand) {
        out.push_back(node);
        continue;
      }
      for (int64_t q = a.child_ptr[id - N]; q < a.child_ptr[id - N + 1]; ++q) next.push_back(q);
    }
    frontier.swap(next);
  }
}

// SH colour along dir (not normalised) from the DC term dc [3] and the higher coefficients rest [(k-1), 3]
// (channel innermost), gsplat's +0.5 and clamp at 0.
inline void sh_colour(int degree, float dx, float dy, float dz, const float* dc, const float* rest, float col[3]) {
  const float n = std::max(std::sqrt(dx * dx + dy * dy + dz * dz), 1e-12f);
  const float x = dx / n, y = dy / n, z = dz / n;
  float basis[16];
  int k = 1;
  basis[0] = SH_C0;
  if (degree >= 1) {
    basis[1] = -SH_C1 * y;
    basis[2] = SH_C1 * z;
    basis[3] = -SH_C1 * x;
    k = 4;
  }
  if (degree >= 2) {
    const float xx = x * x, yy = y * y, zz = z * z, xy = x * y, yz = y * z, xz = x * z;
    basis[4] = SH_C2[0] * xy;
    basis[5] = SH_C2[1] * yz;
    basis[6] = SH_C2[2] * (2.0f * zz - xx - yy);
    basis[7] = SH_C2[3] * xz;
    basis[8] = SH_C2[4] * (xx - yy);
    k = 9;
    if (degree >= 3) {
      basis[9] = SH_C3[0] * y * (3 * xx - yy);
      basis[10] = SH_C3[1] * xy * z;
      basis[11] = SH_C3[2] * y * (4 * zz - xx - yy);
      basis[12] = SH_C3[3] * z * (2 * zz - 3 * xx - 3 * yy);
      basis[13] = SH_C3[4] * x * (4 * zz - xx - yy);
      basis[14] = SH_C3[5] * z * (xx - yy);
      basis[15] = SH_C3[6] * x * (xx - 3 * yy);
      k = 16;
    }
  }
  float sum[3] = {basis[0] * dc[0], basis[0] * dc[1], basis[0] * dc[2]};
  for (int i = 1; i < k; ++i)
    for (int ch = 0; ch < 3; ++ch) sum[ch] += basis[i] * rest[(i - 1) * 3 + ch];
  for (int ch = 0; ch < 3; ++ch) col[ch] = std::max(sum[ch] + 0.5f, 0.0f);
}

// The reference's packed EWA projection and screen-space culls (packed._project_pairs,
// projection.screen_space) of one Gaussian in one camera; false when culled.
bool project(const WlArgs& a, int64_t cam, const float m[3], const float* cov6, float opac, Splat& s) {
  const float* V = a.viewmat + cam * 16;
  const float* Kc = a.Ks + cam * 9;
  const float R[9] = {V[0], V[1], V[2], V[4], V[5], V[6], V[8], V[9], V[10]};
  float p[3];
  for (int k = 0; k < 3; ++k) p[k] = R[3 * k] * m[0] + R[3 * k + 1] * m[1] + R[3 * k + 2] * m[2] + V[4 * k + 3];
  const float x = p[0], y = p[1], zr = p[2];
  const float fx = Kc[0], fy = Kc[4], cx = Kc[2], cy = Kc[5];
  const float W = (float)a.width, H = (float)a.height;
  float u, v, j[6];
  if (a.camera_model == 0) {
    const float z = std::fabs(zr) > 1e-6f ? zr : 1e-6f;
    const float tan_fovx = 0.5f * W / fx, tan_fovy = 0.5f * H / fy;
    const float lim_x_pos = (W - cx) / fx + 0.3f * tan_fovx, lim_x_neg = cx / fx + 0.3f * tan_fovx;
    const float lim_y_pos = (H - cy) / fy + 0.3f * tan_fovy, lim_y_neg = cy / fy + 0.3f * tan_fovy;
    const float rz = 1.0f / z;
    const float tx = z * std::min(std::max(x * rz, -lim_x_neg), lim_x_pos);
    const float ty = z * std::min(std::max(y * rz, -lim_y_neg), lim_y_pos);
    u = fx * x * rz + cx;
    v = fy * y * rz + cy;
    j[0] = fx * rz; j[1] = 0.0f; j[2] = -fx * tx * rz * rz;
    j[3] = 0.0f; j[4] = fy * rz; j[5] = -fy * ty * rz * rz;
  } else {  // equidistant fisheye (projection._fisheye_jacobian)
    const float z = zr, eps = 1e-7f;
    const float xy_len = std::sqrt(x * x + y * y) + eps;
    const float theta = std::atan2(xy_len, z + eps);
    u = x * fx * theta / xy_len + cx;
    v = y * fy * theta / xy_len + cy;
    const float x2 = x * x + eps, y2 = y * y, xy = x * y, x2y2 = x2 + y2;
    const float inv = 1.0f / (x2y2 + z * z);
    const float b = std::atan2(xy_len, z) / xy_len / x2y2;
    const float aa = z * inv / x2y2;
    j[0] = fx * (x2 * aa + y2 * b); j[1] = fx * xy * (aa - b); j[2] = -fx * x * inv;
    j[3] = fy * xy * (aa - b); j[4] = fy * (y2 * aa + x2 * b); j[5] = -fy * y * inv;
  }
  // T = J R (two rows), cov2d = T cov T^T with the symmetrised covariance (packed._sym6 / _ewa_cov2d)
  float t0[3], t1[3];
  for (int k = 0; k < 3; ++k) {
    if (a.camera_model == 0) {
      t0[k] = j[0] * R[k] + j[2] * R[6 + k];
      t1[k] = j[4] * R[3 + k] + j[5] * R[6 + k];
    } else {
      t0[k] = j[0] * R[k] + j[1] * R[3 + k] + j[2] * R[6 + k];
      t1[k] = j[3] * R[k] + j[4] * R[3 + k] + j[5] * R[6 + k];
    }
  }
  const float xx = cov6[0], xy = cov6[1], xz = cov6[2], yy = cov6[3], yz = cov6[4], zz = cov6[5];
  const float s0[3] = {xx * t0[0] + xy * t0[1] + xz * t0[2], xy * t0[0] + yy * t0[1] + yz * t0[2],
                       xz * t0[0] + yz * t0[1] + zz * t0[2]};
  const float s1[3] = {xx * t1[0] + xy * t1[1] + xz * t1[2], xy * t1[0] + yy * t1[1] + yz * t1[2],
                       xz * t1[0] + yz * t1[1] + zz * t1[2]};
  auto dot = [](const float* p, const float* q) { return p[0] * q[0] + p[1] * q[1] + p[2] * q[2]; };
  float c00 = dot(t0, s0), c01 = 0.5f * (dot(t0, s1) + dot(t1, s0)), c11 = dot(t1, s1);
  const float det_orig = c00 * c11 - c01 * c01;
  c00 = c00 + a.eps2d;
  c11 = c11 + a.eps2d;
  const float det = c00 * c11 - c01 * c01;
  if (!(det > 0.0f) || !(zr >= a.near_plane) || !(zr <= a.far_plane)) return false;
  float op = opac;
  if (a.antialiased) op = op * std::sqrt(std::max(det_orig / det, 0.0f));
  if (!(op >= ALPHA_MIN)) return false;
  // one log: log(255 op) is the opacity-aware extent's log(op / (1/255)) (projection.screen_space) and the tile
  // test's limit; it rounds differently from the reference's quotient in the last bit only, which can move a
  // ceil'd radius by one pixel where every pixel it adds is below the 1/255 threshold anyway
  const float lo = std::log(std::max(op, 1.17549435e-38f));
  const float l255 = lo + 5.54126354515843f;
  const float extend = std::min(RADIUS_SIGMAS, std::sqrt(2.0f * std::max(l255, 0.0f)));
  const float rx = std::ceil(extend * std::sqrt(std::max(c00, 0.0f)));
  const float ry = std::ceil(extend * std::sqrt(std::max(c11, 0.0f)));
  if (rx <= a.radius_clip && ry <= a.radius_clip) return false;
  if (!(u + rx > 0.0f && u - rx < W && v + ry > 0.0f && v - ry < H)) return false;
  if (!std::isfinite(u) || !std::isfinite(v)) return false;
  if (!((int)rx > 0 && (int)ry > 0)) return false;
  s.mx = u; s.my = v;
  s.a = c11 / det; s.b = -c01 / det; s.c = c00 / det;
  s.limit = l255 + 1e-3f;  // binning._tile_test_rows: log(255 o) + 1e-3
  s.lo = lo;
  s.depth = zr;
  s.rx = (int)rx; s.ry = (int)ry;
  return true;
}

// The reference's exact tile test (binning._touches_tile): may the splat reach alpha >= 1/255 at some pixel
// centre of the tile at box offset (dx, dy)? ox, oy: the box's first pixel centre minus the mean.
inline bool touches(float ox, float oy, float ha, float hc, float b, float nb_c, float nb_a, float limit, int dx,
                    int dy) {
  const float X0 = ox + dx * TS, Y0 = oy + dy * TS;
  const float X1 = X0 + (TS - 1), Y1 = Y0 + (TS - 1);
  const float ex = std::max(X0, std::min(X1, 0.0f));
  const float ey = std::max(Y0, std::min(Y1, 0.0f));
  auto sigma = [&](float u, float v) { return ha * u * u + hc * v * v + b * u * v; };
  const float on_x = sigma(ex, std::min(std::max(nb_c * ex, Y0), Y1));
  const float on_y = sigma(std::min(std::max(nb_a * ey, X0), X1), ey);
  return std::min(on_x, on_y) <= limit;
}

// Eight pixels at a time (GCC vector extensions: AVX2 where the build targets it, two SSE halves otherwise).
typedef float v8f __attribute__((vector_size(32)));
typedef int32_t v8i __attribute__((vector_size(32)));

inline v8f splat8(float x) { return v8f{x, x, x, x, x, x, x, x}; }

// exp(x) for x in [-30, 0.1] to ~2 ulp (Cephes' expf polynomial), lane-wise.
__attribute__((optimize("fp-contract=fast"))) inline v8f exp8(v8f x) {
  const v8f t = x * 1.44269504088896341f + 0.5f;
  v8i i = __builtin_convertvector(t, v8i);  // truncation; one down where that rounded a negative up
  i = i + (t < __builtin_convertvector(i, v8f));
  const v8f fx = __builtin_convertvector(i, v8f);
  v8f r = x - fx * 0.693359375f;
  r = r - fx * -2.12194440e-4f;
  const v8f z = r * r;
  v8f y = splat8(1.9875691500e-4f);
  y = y * r + 1.3981999507e-3f;
  y = y * r + 8.3334519073e-3f;
  y = y * r + 4.1665795894e-2f;
  y = y * r + 1.6666665459e-1f;
  y = y * r + 5.0000001201e-1f;
  y = y * z + r + 1.0f;
  return y * (v8f)((i + 127) << 23);
}

// Tile-local pixel-centre coordinates of the 16 pixels (row-major: u = column - 1.5, v = row - 1.5) as two
// halves of eight, their squares and products.
const v8f GU = {-1.5f, -0.5f, 0.5f, 1.5f, -1.5f, -0.5f, 0.5f, 1.5f};
const v8f GU2 = GU * GU;
const v8f GV[2] = {{-1.5f, -1.5f, -1.5f, -1.5f, -0.5f, -0.5f, -0.5f, -0.5f},
                   {0.5f, 0.5f, 0.5f, 0.5f, 1.5f, 1.5f, 1.5f, 1.5f}};
static_assert(TS == 4, "the pixel grid is for 4x4 tiles");

// Front to back over one tile's list (rasterize.forward_chunk, one entry at a time): T [2] transmittance in/out
// (pixels 0-7, 8-15), acc [5][2] += w (r, g, b, depth, 1). The quadratic is the reference's, tile-local.
inline bool any8(v8i m) {
  uint64_t q[4];
  std::memcpy(q, &m, 32);
  return (q[0] | q[1] | q[2] | q[3]) != 0;
}

// (Here, and only here, a*b+c may become one fused multiply-add: the composite is held to the reference at
// float rounding, ~1e-6, not bit for bit.)
__attribute__((optimize("fp-contract=fast")))
void composite_tile(const Splat* splats, const int* list, int n, float ccx, float ccy, float th, v8f* T,
                    v8f (*acc)[2]) {
  const v8f zero = splat8(0.0f), m30 = splat8(-30.0f), amax = splat8(ALPHA_MAX), thv = splat8(th),
            eps = splat8(T_EPS);
  // exp(s) > th needs s > log(th); below log(th) - 1e-3 no lane of a half can pass the threshold
  const v8f skip = splat8(std::log(th) - 1e-3f);
  for (int e = 0; e < n; ++e) {
    const Splat& g = splats[list[e]];
    const float mx = g.mx - ccx, my = g.my - ccy;
    const float amb = g.a * mx + g.b * my, bmc = g.b * mx + g.c * my;
    const float q0 = -0.5f * g.a, q1 = -0.5f * g.c, q2 = -g.b, q3 = amb, q4 = bmc;
    const float q5 = g.lo - 0.5f * (mx * amb + my * bmc);
    const v8f X = (q5 + GU * q3) + GU2 * q0;
    v8i alive = v8i{} ;
    for (int h = 0; h < 2; ++h) {
      v8f s = (GV[h] * q4 + (GV[h] * GV[h]) * q1) + X;
      s = s + (GV[h] * GU) * q2;
      if (!any8(s > skip)) {  // every pixel of this half below the 1/255 threshold: nothing changes
        alive |= T[h] > zero;
        continue;
      }
      s = s < m30 ? m30 : s;
      v8f al = exp8(s);
      al = al < amax ? al : amax;
      const v8f Tp = T[h];
      const v8f nT = Tp * (1.0f - al);
      const v8i use = al > thv;
      const v8i stop = nT <= eps;  // the pixel stops here, this splat excluded (a finished pixel: Tp = nT = 0)
      const v8f wgt = (use & ~stop) ? al * Tp : zero;
      T[h] = stop ? zero : (use ? nT : Tp);
      acc[0][h] += wgt * g.col[0];
      acc[1][h] += wgt * g.col[1];
      acc[2][h] += wgt * g.col[2];
      acc[3][h] += wgt * g.depth;
      acc[4][h] += wgt;
      alive |= T[h] > zero;
    }
    int any = 0;
    for (int k = 0; k < 8; ++k) any |= alive[k];
    if (!any) return;
  }
}

// Stable LSD radix sort of `keys` by their high 32 bits (8-bit digits; a digit all keys share is skipped).
void radix_sort_high(std::vector<uint64_t>& keys, std::vector<uint64_t>& tmp) {
  const size_t n = keys.size();
  tmp.resize(n);
  for (int shift = 32; shift < 64; shift += 8) {
    size_t count[257] = {0};
    for (uint64_t k : keys) ++count[((k >> shift) & 0xFF) + 1];
    if (count[((keys.empty() ? 0 : keys[0] >> shift) & 0xFF) + 1] == n) continue;
    for (int d = 0; d < 256; ++d) count[d + 1] += count[d];
    for (uint64_t k : keys) tmp[count[(k >> shift) & 0xFF]++] = k;
    keys.swap(tmp);
  }
}

struct Scratch {
  std::vector<int64_t> nodes, frontier, next;
  std::vector<Splat> splats, sorted;
  std::vector<uint64_t> keys, keys_tmp, entries;
  std::vector<int> start, list, fill;
};

void render_camera(const WlArgs& a, int64_t cam, Scratch& w) {
  const int Wd = a.width, Ht = a.height;
  const int TW = (Wd + TS - 1) / TS, TH = (Ht + TS - 1) / TS, NT = TW * TH;
  const int64_t N = a.N, K = a.K;
  // 1. the cut (or every leaf)
  if (a.use_cut) {
    cut_camera(a, cam, w.nodes, w.frontier, w.next);
  } else {
    w.nodes.resize(N);
    std::iota(w.nodes.begin(), w.nodes.end(), int64_t(0));
  }
  if (a.drawn) a.drawn[cam] = (int64_t)w.nodes.size() + a.M;
  // 2. projection and colours
  w.splats.clear();
  const float* cp = a.campos + cam * 3;
  Splat s;
  const size_t Q = w.nodes.size();
  for (size_t q = 0; q < Q; ++q) {
    const int64_t node = w.nodes[q];
    if (q + 8 < Q) {
      const float* ahead_rec = a.rec + w.nodes[q + 8] * 16;
      __builtin_prefetch(ahead_rec);
      if (a.sh_degree > 0 && a.want_rgb && q + 4 < Q) {  // the higher SH coefficients of a record read before
        const int64_t ahead = node_id(a.rec + w.nodes[q + 4] * 16);
        const float* rest = ahead < N ? a.leaf_rest + ahead * (K - 1) * 3 : a.node_sh + ((ahead - N) * K + 1) * 3;
        for (int64_t line = 0; line < (K - 1) * 3; line += 16) __builtin_prefetch(rest + line);
      }
    }
    const float* rec = a.rec + node * 16;
    if (!project(a, cam, rec, rec + 4, rec[10], s)) continue;
    if (a.want_rgb) {
      const int64_t id = node_id(rec);
      const float* rest = id < N ? a.leaf_rest + id * (K - 1) * 3 : a.node_sh + ((id - N) * K + 1) * 3;
      sh_colour(a.sh_degree, rec[0] - cp[0], rec[1] - cp[1], rec[2] - cp[2], rec + 11, rest, s.col);
    }
    w.splats.push_back(s);
  }
  for (int64_t e = 0; e < a.M; ++e) {  // extra rows: constant colour (its SH is the DC term alone)
    const int64_t row = cam * a.M + e;
    const float* c9 = a.ex_cov + row * 9;
    const float cov6[6] = {c9[0], 0.5f * (c9[1] + c9[3]), 0.5f * (c9[2] + c9[6]), c9[4], 0.5f * (c9[5] + c9[7]), c9[8]};
    if (!project(a, cam, a.ex_means + row * 3, cov6, a.ex_opac[row], s)) continue;
    for (int ch = 0; ch < 3; ++ch) {
      const float coef = (a.ex_rgb[row * 3 + ch] - 0.5f) / SH_C0;
      s.col[ch] = std::max(SH_C0 * coef + 0.5f, 0.0f);
    }
    w.splats.push_back(s);
  }
  const int V = (int)w.splats.size();
  if (a.pairs) a.pairs[cam] = V;
  // 3. depth order (stable, as the reference's radix sort of the depth bits): depths are >= near_plane > 0,
  // so their float bits order as integers; the splat's index in the low bits breaks ties by input order
  w.keys.resize(V);
  for (int i = 0; i < V; ++i) {
    uint32_t bits;
    std::memcpy(&bits, &w.splats[i].depth, 4);
    w.keys[i] = (uint64_t(bits) << 32) | uint32_t(i);
  }
  radix_sort_high(w.keys, w.keys_tmp);
  w.sorted.resize(V);
  for (int i = 0; i < V; ++i) w.sorted[i] = w.splats[uint32_t(w.keys[i])];
  // 4. tile lists: (tile, splat) entries in depth order, then a stable counting sort by tile
  w.entries.resize(std::max<size_t>(w.entries.capacity(), 1024));
  size_t n_entries = 0;
  for (int i = 0; i < V; ++i) {
    const Splat& g = w.sorted[i];
    const int x0 = std::min(std::max((int)std::floor((g.mx - g.rx) / TS), 0), TW);
    const int x1 = std::min(std::max((int)std::ceil((g.mx + g.rx) / TS), 0), TW);
    const int y0 = std::min(std::max((int)std::floor((g.my - g.ry) / TS), 0), TH);
    const int y1 = std::min(std::max((int)std::ceil((g.my + g.ry) / TS), 0), TH);
    const float ox = x0 * TS + 0.5f - g.mx, oy = y0 * TS + 0.5f - g.my;
    const float ha = 0.5f * g.a, hc = 0.5f * g.c, nb_c = -g.b / g.c, nb_a = -g.b / g.a;
    const size_t box = size_t(std::max(x1 - x0, 0)) * size_t(std::max(y1 - y0, 0));
    if (w.entries.size() < n_entries + box) w.entries.resize(2 * (n_entries + box));
    uint64_t* out = w.entries.data();
    for (int ty = y0; ty < y1; ++ty)
      for (int tx = x0; tx < x1; ++tx) {  // written always, kept when it touches: no branch to mispredict
        out[n_entries] = (uint64_t(ty * TW + tx) << 32) | uint32_t(i);
        n_entries += touches(ox, oy, ha, hc, g.b, nb_c, nb_a, g.limit, tx - x0, ty - y0);
      }
  }
  w.entries.resize(n_entries);
  w.start.assign(NT + 1, 0);
  for (uint64_t e : w.entries) ++w.start[(e >> 32) + 1];
  for (int t = 0; t < NT; ++t) w.start[t + 1] += w.start[t];
  w.list.resize(w.entries.size());
  w.fill.assign(w.start.begin(), w.start.end() - 1);
  for (uint64_t e : w.entries) w.list[w.fill[e >> 32]++] = uint32_t(e);
  // 5. composite, tile by tile
  const float th = std::nextafter(ALPHA_MIN, 0.0f);
  const int64_t img = cam * (int64_t)Wd * Ht;
  v8f Tv[2], accv[5][2];
  float* T = (float*)Tv;  // pixel p is lane p % 8 of half p / 8
  float* acc[5];
  for (int k = 0; k < 5; ++k) acc[k] = (float*)accv[k];
  for (int ty = 0; ty < TH; ++ty) {
    for (int tx = 0; tx < TW; ++tx) {
      const int t = ty * TW + tx;
      for (int p = 0; p < 16; ++p) {
        T[p] = tx * TS + p % TS < Wd && ty * TS + p / TS < Ht ? 1.0f : 0.0f;  // edge tiles: padding pixels off
        for (int k = 0; k < 5; ++k) acc[k][p] = 0.0f;
      }
      composite_tile(w.sorted.data(), w.list.data() + w.start[t], w.start[t + 1] - w.start[t],
                     tx * TS + TS / 2.0f, ty * TS + TS / 2.0f, th, Tv, accv);
      for (int p = 0; p < 16; ++p) {
        const int px = tx * TS + p % TS, py = ty * TS + p / TS;
        if (px >= Wd || py >= Ht) continue;
        const int64_t o = img + (int64_t)py * Wd + px;
        const float al = acc[4][p];
        if (a.alpha) a.alpha[o] = al;
        if (a.rgb) {
          for (int ch = 0; ch < 3; ++ch) {
            float v = acc[ch][p];
            if (a.bg) v = v + (1.0f - al) * a.bg[cam * 3 + ch];
            a.rgb[o * 3 + ch] = std::min(std::max(v, 0.0f), 1.0f);
          }
        }
        if (a.depth) a.depth[o] = a.depth_mode == 2 ? acc[3][p] / std::max(al, 1e-10f) : acc[3][p];
      }
    }
  }
}

template <class Fn>
void for_cameras(int64_t C, int threads, Fn fn) {
  const int n = (int)std::max<int64_t>(1, std::min<int64_t>(threads, C));
  std::atomic<int64_t> next{0};
  auto work = [&](Scratch& w) {
    for (int64_t c; (c = next.fetch_add(1)) < C;) fn(c, w);
  };
  std::vector<std::thread> pool;
  for (int i = 1; i < n; ++i) pool.emplace_back([&]() {
    Scratch w;
    work(w);
  });
  static thread_local Scratch caller;  // the calling thread's buffers outlive the call: no reallocation per step
  work(caller);
  for (auto& t : pool) t.join();
}

struct CutResult {
  std::vector<std::vector<int64_t>> per_camera;
};

}  // namespace

extern "C" {

int wl_abi_version() { return 4; }

// Render every camera of `a` into its outputs.
void wl_render(const WlArgs* a) {
  for_cameras(a->C, a->threads, [&](int64_t c, Scratch& w) { render_camera(*a, c, w); });
}

// The cut alone, every camera: returns a handle; wl_cut_total / wl_cut_fetch read it, wl_cut_free frees it.
void* wl_cut(const WlArgs* a) {
  auto* r = new CutResult;
  r->per_camera.resize(a->C);
  for_cameras(a->C, a->threads, [&](int64_t c, Scratch& w) {
    cut_camera(*a, c, r->per_camera[c], w.frontier, w.next);
    for (int64_t& slot : r->per_camera[c]) slot = node_id(a->rec + slot * 16);  // slots -> node ids
  });
  return r;
}

int64_t wl_cut_total(void* h) {
  int64_t n = 0;
  for (auto& v : static_cast<CutResult*>(h)->per_camera) n += (int64_t)v.size();
  return n;
}

// cam [total], node [total] grouped by camera, each camera's nodes in the reference's order
void wl_cut_fetch(void* h, int64_t* cam, int64_t* node) {
  int64_t k = 0, c = 0;
  for (auto& v : static_cast<CutResult*>(h)->per_camera) {
    for (int64_t id : v) {
      cam[k] = c;
      node[k++] = id;
    }
    ++c;
  }
}

void wl_cut_free(void* h) { delete static_cast<CutResult*>(h); }

}  // extern "C"
