// DistanceIndex: an Embree 3 BVH over a mesh's triangles for exact closest-point queries, and the cumulative
// areas that area-uniform samples are drawn from.
//
// Why Embree: a well-kept, widely used BVH (Debian's libembree-dev) whose rtcPointQuery culls nodes against a
// shrinking sphere and calls back per candidate triangle, leaving the exact distance to us. Measured here
// (CPU seconds, bench/compare_bench.cpp and the 10 M vs 100 k comparison in the report): a 10 M-triangle
// BVH builds in 1.6 s; queries run at about 0.9 M/s a core against 10 M triangles and 2.6 M/s against 100 k;
// the whole 10 M vs 100 k comparison (1 M samples each way plus 5 M vertices) costs about 5 s of CPU, far
// inside the minute allowed. Profiles put about half of the query time inside Embree, so a hand-written BVH
// could save at most that half; it was not written.
#include "compare_index.h"

#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <limits>
#include <new>
#include <utility>

#include "ocsimp/core/error.h"

namespace ocsimp {

namespace {

Vec3d closest_point_on_segment(const Vec3d& p, const Vec3d& a, const Vec3d& b) {
  const Vec3d ab = b - a;
  const double length_squared = ab.squaredNorm();
  if (!(length_squared > 0)) return a;
  const double t = std::clamp((p - a).dot(ab) / length_squared, 0.0, 1.0);
  return a + t * ab;
}

// Of two candidate points, the one nearer to p (the first on ties, so results do not depend on luck).
Vec3d nearer(const Vec3d& p, const Vec3d& x, const Vec3d& y) {
  return (x - p).squaredNorm() <= (y - p).squaredNorm() ? x : y;
}

// The box of a triangle's corners: what the index's leaves are culled by, and what decides its build.
Box3 triangle_box(const Vec3d& a, const Vec3d& b, const Vec3d& c) {
  return {a.cwiseMin(b).cwiseMin(c), a.cwiseMax(b).cwiseMax(c)};
}

}  // namespace

Vec3d closest_point_on_triangle(const Vec3d& p, const Vec3d& a, const Vec3d& b, const Vec3d& c) {
  // Work from the corner opposite the longest edge: it has the largest angle, so the plane normal computed
  // there is as accurate as the triangle allows.
  const double ab2 = (b - a).squaredNorm(), bc2 = (c - b).squaredNorm(), ca2 = (a - c).squaredNorm();
  const Vec3d* o = &a;
  const Vec3d* u = &b;
  const Vec3d* v = &c;
  if (ab2 >= bc2 && ab2 >= ca2) {
    o = &c, u = &a, v = &b;
  } else if (ca2 >= bc2 && ca2 >= ab2) {
    o = &b, u = &c, v = &a;
  }
  const Vec3d e0 = *u - *o, e1 = *v - *o, op = p - *o;
  const Vec3d n = e0.cross(e1);
  const double nn = n.squaredNorm();
  // nn = |e0|^2 |e1|^2 sin^2(angle at o): below sine 1e-6 the normal is noise, and the triangle is so thin
  // that its edges stand for it.
  if (!(nn > 1e-12 * e0.squaredNorm() * e1.squaredNorm())) {
    return nearer(p, nearer(p, closest_point_on_segment(p, a, b), closest_point_on_segment(p, b, c)),
                  closest_point_on_segment(p, c, a));
  }
  // Barycentric weights of u and v for p's projection onto the plane.
  const double s = op.cross(e1).dot(n) / nn;
  const double t = e0.cross(op).dot(n) / nn;
  if (s >= 0 && t >= 0 && s + t <= 1) return *o + s * e0 + t * e1;
  // The projection is outside. The nearest point of a convex polygon lies on an edge whose line separates
  // the point from the polygon, i.e. an edge opposite a corner with a negative weight; check only those.
  Vec3d best = Vec3d::Constant(std::numeric_limits<double>::infinity());
  if (s < 0) best = nearer(p, best, closest_point_on_segment(p, *o, *v));
  if (t < 0) best = nearer(p, best, closest_point_on_segment(p, *o, *u));
  if (s + t > 1) best = nearer(p, best, closest_point_on_segment(p, *u, *v));
  return best;
}

DistanceIndex::Impl::~Impl() {
  if (scene) rtcReleaseScene(scene);
  if (device) rtcReleaseDevice(device);
}

namespace {

// The sum over a mesh's triangles of their boxes' areas (half the surface of each) against the sum of their
// areas, above which the BVH is built with spatial splits. It counts, roughly, how many boxes a point of the
// surface lies in: 3 to 4.5 for meshes of well-shaped triangles in any orientation (bunny 3.8, fandisk 2.8,
// teapot 4.3, a generated 1 M-triangle scan 4.1); 15 and up where long slivers lie across the axes (a CAD
// cylinder of 2,000 segments with fan caps 137, a cone of 5,000 segments 3,084).
constexpr double kLooseBoxes = 8;

// References a triangle may get in a build with spatial splits, relative to the triangle count: more
// references, faster queries, more memory. Measured on cones of fan caps and side slivers, `compare` of the
// mesh against itself with 100 k samples, against the Morton build's 434 s and 299 MB on 1 M triangles:
//   replications   1 M-triangle cone    20 k-triangle cone (1 M samples against its decimation)
//   2              250 s, 308 MB
//   4              172 s, 495 MB
//   8              132 s, 878 MB        11.8 s (Embree's own default: 40 s; 32: no faster, twice the memory)
// So 8 up to kSplitManyTriangles, where the index costs at most about 0.9 GB; 2 above, which costs no more
// memory than the Morton build and still queries 1.7 times as fast.
constexpr int kSplitReplications = 8, kSplitReplicationsLarge = 2;
constexpr std::size_t kSplitManyTriangles = std::size_t{1} << 20;

// The triangles of `mesh` that do not repeat an earlier one exactly (the same three positions, in any order),
// ascending; empty when none repeats. A BVH query near a triangle stored k times visits all k copies:
// `compare` of a file of 1,000 copies of one triangle with itself took 39 s, and 10,000 copies did not finish
// in two minutes. Found by sorting hashes of the corner positions, so that a mesh without repeats costs a
// parallel pass and a sort of 16 bytes a triangle (freed before the BVH is built, which takes more).
std::vector<Index> first_copies(const IndexedMesh& mesh) {
  const std::size_t n = mesh.triangles.size();
  auto sorted_keys = [&](std::size_t f) {
    std::array<PositionKey, 3> k{PositionKey(mesh.positions[mesh.triangles[f][0]]),
                                 PositionKey(mesh.positions[mesh.triangles[f][1]]),
                                 PositionKey(mesh.positions[mesh.triangles[f][2]])};
    std::sort(k.begin(), k.end(), [](const PositionKey& a, const PositionKey& b) {
      return std::lexicographical_compare(a.bits, a.bits + 3, b.bits, b.bits + 3);
    });
    return k;
  };
  std::vector<std::pair<std::uint64_t, Index>> keyed(n);
  tbb::parallel_for(std::size_t{0}, n, [&](std::size_t f) {
    const auto k = sorted_keys(f);
    std::uint64_t h = k[0].hash();
    h = (h ^ k[1].hash()) * 0x9E3779B97F4A7C15ull;
    h = (h ^ k[2].hash()) * 0xBF58476D1CE4E5B9ull;
    keyed[f] = {h ^ (h >> 31), static_cast<Index>(f)};
  });
  tbb::parallel_sort(keyed.begin(), keyed.end());
  std::vector<std::uint8_t> repeats(n, 0);
  bool any = false;
  for (std::size_t i = 0; i < n;) {
    std::size_t end = i + 1;
    while (end < n && keyed[end].first == keyed[i].first) ++end;
    // Within a run of equal hashes (ids ascending), a triangle repeats an earlier one when their keys match.
    for (std::size_t j = i + 1; j < end; ++j) {
      const auto kj = sorted_keys(keyed[j].second);
      for (std::size_t e = i; e < j && !repeats[keyed[j].second]; ++e) {
        if (sorted_keys(keyed[e].second) == kj) repeats[keyed[j].second] = 1, any = true;
      }
    }
    i = end;
  }
  std::vector<Index> first;
  if (!any) return first;
  for (std::size_t f = 0; f < n; ++f)
    if (!repeats[f]) first.push_back(static_cast<Index>(f));
  return first;
}

void remember_embree_error(void* user, RTCError code, const char* message) {
  auto* impl = static_cast<DistanceIndex::Impl*>(user);
  impl->device_error = message ? message : "";
  if (code == RTC_ERROR_OUT_OF_MEMORY) impl->device_error = "out of memory";
}

[[noreturn]] void throw_embree_error(const DistanceIndex::Impl& impl, const char* what) {
  const RTCError code = impl.device ? rtcGetDeviceError(impl.device) : rtcGetDeviceError(nullptr);
  if (code == RTC_ERROR_OUT_OF_MEMORY) throw std::bad_alloc();
  throw Error(impl.name, {},
              std::string(what) + " failed in Embree" +
                  (impl.device_error.empty() ? std::string() : ": " + impl.device_error));
}

}  // namespace

DistanceIndex::DistanceIndex(const IndexedMesh& mesh, std::string name) : impl_(std::make_unique<Impl>()) {
  Impl& impl = *impl_;
  impl.name = std::move(name);
  impl.origin = mesh.origin;
  if (mesh.triangles.empty()) throw Error(impl.name, {}, "the mesh has no triangles to measure");
  if (!mesh.origin.allFinite()) throw Error(impl.name, {}, "the mesh's origin is not a finite point");
  const std::size_t vertex_count = mesh.positions.size();
  for (std::size_t v = 0; v < vertex_count; ++v) {
    if (!mesh.positions[v].allFinite())
      throw Error(impl.name, {}, "vertex " + std::to_string(v) + " has a coordinate that is not finite");
  }
  std::vector<std::uint8_t> used(vertex_count, 0);
  for (std::size_t f = 0; f < mesh.triangles.size(); ++f) {
    for (Index v : mesh.triangles[f]) {
      if (v >= vertex_count)
        throw Error(impl.name, {},
                    "triangle " + std::to_string(f) + " refers to vertex " + std::to_string(v) + " of only " +
                        std::to_string(vertex_count));
      used[v] = 1;
    }
  }
  for (std::size_t v = 0; v < vertex_count; ++v) {
    if (!used[v]) continue;
    impl.referenced_vertices.push_back(static_cast<Index>(v));
    impl.bounds.add(mesh.positions[v]);
  }
  // The box of the surface, so a stray vertex no face uses does not shrink every percentage of its diagonal
  // (one at (100, 100, 100) beside a unit square, 120 times); a mesh of no faces has only its vertices.
  if (impl.referenced_vertices.empty()) impl.bounds = mesh.bounds();
  // A mesh far from zero for its size (a float scan at UTM northings, 4e6 out and 15 wide) is indexed about
  // its own centre. Embree's float culling is widened by about 1e-6 of the coordinates, which there exceeded
  // the mesh: every query visited every triangle, and comparing such a mesh with itself ran for hours. The
  // shift is a float near the centre, on each axis whose coordinates stay within half to twice it, so that
  // every position minus it is exact (Sterbenz).
  Vec3d shift = Vec3d::Zero();
  if (!impl.bounds.empty()) {
    const Vec3d center = impl.bounds.center(), extent = impl.bounds.extent();
    for (int a = 0; a < 3; ++a)
      if (std::abs(center[a]) > extent[a]) shift[a] = static_cast<double>(static_cast<float>(center[a]));
    impl.bounds.lo -= shift;
    impl.bounds.hi -= shift;
    impl.origin += shift;
  }
  impl.coordinate_scale =
      std::max(impl.bounds.lo.cwiseAbs().maxCoeff(), impl.bounds.hi.cwiseAbs().maxCoeff());
  // Below float's normal range the coordinates are subnormal, which Embree's threads read as zero (they set
  // the flush-to-zero modes): every query then missed the mesh and was called "too far from this mesh".
  if (impl.coordinate_scale > 0 && impl.coordinate_scale < std::numeric_limits<float>::min()) {
    char text[96];
    std::snprintf(text, sizeof text, "its largest coordinate, %.3g, is below float's normal range (%.3g)",
                  impl.coordinate_scale, double(std::numeric_limits<float>::min()));
    throw Error(impl.name, {}, std::string("the mesh is too small to measure: ") + text);
  }
  if (impl.coordinate_scale > 0 && (impl.coordinate_scale < 0x1p-20 || impl.coordinate_scale > 0x1p20))
    impl.embree_scale = std::ldexp(1.0, -std::ilogb(impl.coordinate_scale));

  const int replications =
      mesh.triangles.size() <= kSplitManyTriangles ? kSplitReplications : kSplitReplicationsLarge;
  impl.device =
      rtcNewDevice(("verbose=0,max_spatial_split_replications=" + std::to_string(replications)).c_str());
  if (!impl.device) throw_embree_error(impl, "creating a device");
  rtcSetDeviceErrorFunction(impl.device, remember_embree_error, &impl);
  impl.scene = rtcNewScene(impl.device);
  if (!impl.scene) throw_embree_error(impl, "creating a scene");
  // Sized before the geometry exists, so that nothing between its creation and its release can throw.
  constexpr std::size_t grain = std::size_t{1} << 14;
  std::vector<double>& cumulative = impl.cumulative_area;
  cumulative.resize(mesh.triangles.size() + 1);
  std::vector<double> box_area((mesh.triangles.size() + grain - 1) / grain, 0.0);
  impl.triangle_of_primitive = first_copies(mesh);
  const bool repeats = !impl.triangle_of_primitive.empty();
  const std::size_t primitives = repeats ? impl.triangle_of_primitive.size() : mesh.triangles.size();
  if (repeats) impl.all_corners.resize(3 * mesh.triangles.size());
  RTCGeometry geometry = rtcNewGeometry(impl.device, RTC_GEOMETRY_TYPE_TRIANGLE);
  if (!geometry) throw_embree_error(impl, "creating a geometry");
  auto* positions = static_cast<float*>(rtcSetNewGeometryBuffer(
      geometry, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), vertex_count));
  auto* corners = static_cast<Index*>(rtcSetNewGeometryBuffer(
      geometry, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(Index), primitives));
  if (!positions || !corners) {
    rtcReleaseGeometry(geometry);
    throw_embree_error(impl, "allocating the mesh buffers");
  }
  const auto embree_scale = static_cast<float>(impl.embree_scale);
  for (std::size_t v = 0; v < vertex_count; ++v)
    for (int k = 0; k < 3; ++k)
      positions[3 * v + k] = static_cast<float>(double(mesh.positions[v][k]) - shift[k]) * embree_scale;
  if (!repeats) {
    for (std::size_t f = 0; f < mesh.triangles.size(); ++f)
      for (int k = 0; k < 3; ++k) corners[3 * f + k] = mesh.triangles[f][k];
    impl.corners = corners;
  } else {
    for (std::size_t f = 0; f < mesh.triangles.size(); ++f)
      for (int k = 0; k < 3; ++k) impl.all_corners[3 * f + k] = mesh.triangles[f][k];
    for (std::size_t i = 0; i < primitives; ++i)
      for (int k = 0; k < 3; ++k) corners[3 * i + k] = mesh.triangles[impl.triangle_of_primitive[i]][k];
    impl.corners = impl.all_corners.data();
  }
  impl.positions = positions;
  impl.primitive_corners = corners;
  impl.vertex_count = vertex_count;
  impl.triangle_count = mesh.triangles.size();

  // Areas in parallel, summed in triangle order so the samples never depend on the thread count; with them,
  // the area of each triangle's box (half its surface), which decides the build below.
  cumulative[0] = 0;
  tbb::parallel_for(std::size_t{0}, box_area.size(), [&](std::size_t chunk) {
    const std::size_t end = std::min(impl.triangle_count, (chunk + 1) * grain);
    for (std::size_t f = chunk * grain; f < end; ++f) {
      const Index* t = impl.corners + 3 * f;
      const Vec3d a = impl.vertex(t[0]), b = impl.vertex(t[1]), c = impl.vertex(t[2]);
      cumulative[f + 1] = 0.5 * (b - a).cross(c - a).norm();
      const Box3 box = triangle_box(a, b, c);
      const Vec3d e = box.hi - box.lo;
      box_area[chunk] += e.x() * e.y() + e.y() * e.z() + e.z() * e.x();
    }
  });
  for (std::size_t f = 0; f < impl.triangle_count; ++f) {
    if (cumulative[f + 1] > 0) impl.last_sampled_triangle = f;
    cumulative[f + 1] += cumulative[f];
  }
  double boxes = 0;
  for (double b : box_area) boxes += b;

  // Embree's low-quality (Morton) builder: 3.4x less CPU than its default SAH build on 10 M triangles
  // (1.6 s against 5.4 s) and as fast to query within noise (1.35 s against 1.24-1.34 s for 1 M samples plus
  // 50 k vertices against those 10 M triangles): the previous-closest-point bound does most of the pruning.
  // It takes the LOW settings below; the memory is the same (about 100 bytes a triangle). Long slivers
  // across the axes (the fan caps and sides of a CAD cylinder or cone) defeat any BVH of whole triangles:
  // their boxes are mostly empty and overlap by the hundreds, and every query near them visits them all.
  // There the SAH build with spatial splits (references to clipped parts of a triangle, each with its own
  // tight box; see kSplitReplications) pays for its slower build many times over: `ocsimp compare` of a
  // 20 k-face cone of 5,000 segments against its decimation fell from 51.7 s to 11.8 s, and of an 80 k-face
  // cylinder of 20,000 segments from 36.5 s to 7.2 s.
  const bool loose = boxes > kLooseBoxes * impl.total_area();
  const RTCBuildQuality quality = loose ? RTC_BUILD_QUALITY_HIGH : RTC_BUILD_QUALITY_LOW;
  rtcSetGeometryBuildQuality(geometry, quality);
  rtcSetSceneBuildQuality(impl.scene, quality);
  if (!loose) rtcSetSceneFlags(impl.scene, RTC_SCENE_FLAG_DYNAMIC);
  rtcCommitGeometry(geometry);
  rtcAttachGeometry(impl.scene, geometry);
  rtcReleaseGeometry(geometry);  // the scene keeps it, and with it the buffers above
  rtcCommitScene(impl.scene);
  if (rtcGetDeviceError(impl.device) != RTC_ERROR_NONE) throw_embree_error(impl, "building the BVH");
}

DistanceIndex::DistanceIndex(DistanceIndex&&) noexcept = default;
DistanceIndex& DistanceIndex::operator=(DistanceIndex&&) noexcept = default;
DistanceIndex::~DistanceIndex() = default;

const std::string& DistanceIndex::name() const {
  return impl_->name;
}
std::size_t DistanceIndex::triangle_count() const {
  return impl_->triangle_count;
}
std::size_t DistanceIndex::referenced_vertex_count() const {
  return impl_->referenced_vertices.size();
}
double DistanceIndex::area() const {
  return impl_->total_area();
}
Box3 DistanceIndex::bounds() const {
  return impl_->bounds;
}

Vec3d DistanceIndex::origin() const {
  return impl_->origin;
}

namespace {

struct PointQuery {
  const DistanceIndex::Impl* index;
  Vec3d p;
  // What Embree's float culling may be off by, in its units (see embree_scale): the query point rounded to
  // float, plus rounding in its point-to-box distances. Radii handed to Embree are widened by it so that no
  // triangle that could beat the current best is ever culled, which keeps the answer the exact minimum
  // whatever the traversal order.
  double margin;
  double limit_squared;  // triangles farther than the caller's bound are ignored
  ClosestPoint best;
};

float culling_radius(double distance, double margin) {
  const double widened = distance * (1 + 1e-6) + margin;
  const auto radius = static_cast<float>(widened);
  return static_cast<double>(radius) >= widened
             ? radius
             : std::nextafter(radius, std::numeric_limits<float>::infinity());
}

bool visit_triangle(RTCPointQueryFunctionArguments* args) {
  auto& query = *static_cast<PointQuery*>(args->userPtr);
  const DistanceIndex::Impl& index = *query.index;
  const Index* t = index.primitive_corners + 3 * std::size_t{args->primID};
  const Vec3d a = index.vertex(t[0]), b = index.vertex(t[1]), c = index.vertex(t[2]);
  // Embree culls nodes, not the triangles of a leaf. The distance to the triangle's box is a lower bound that
  // rejects most of them for a fraction of the exact test; the relative slack keeps rounding from ever
  // rejecting a triangle that would tie or win.
  const Box3 box = triangle_box(a, b, c);
  const Vec3d below = box.lo - query.p, above = query.p - box.hi;
  const double box_d2 = below.cwiseMax(above).cwiseMax(0.0).squaredNorm();
  if (box_d2 > std::min(query.best.distance_squared, query.limit_squared) * (1 + 1e-12)) return false;
  const Vec3d point = closest_point_on_triangle(query.p, a, b, c);
  const double d2 = (point - query.p).squaredNorm();
  if (d2 > query.limit_squared) return false;
  if (d2 > query.best.distance_squared) return false;
  // Ties go to the lower triangle id, so the reported point does not depend on the traversal order either.
  const Index triangle = index.triangle_of_primitive.empty() ? static_cast<Index>(args->primID)
                                                             : index.triangle_of_primitive[args->primID];
  if (d2 < query.best.distance_squared ||
      (d2 == query.best.distance_squared && triangle < query.best.triangle)) {
    query.best = {point, d2, triangle};
    const float radius = culling_radius(std::sqrt(d2) * index.embree_scale, query.margin);
    if (radius < args->query->radius) {
      args->query->radius = radius;
      return true;
    }
  }
  return false;
}

}  // namespace

ClosestPoint DistanceIndex::closest_point(const Vec3d& p, double upper_bound) const {
  PointQuery query{impl_.get(), p, 0.0, upper_bound * upper_bound, {}};
  const double scale = impl_->embree_scale;
  const Vec3d scaled = p * scale;
  // Embree ignores points beyond about 1.8e18 (its FLT_LARGE) in its units: a mesh's size or less there.
  if (!p.allFinite()) throw Error(impl_->name, {}, "a point to measure is not finite");
  if (!(scaled.cwiseAbs().maxCoeff() < 1e18))
    throw Error(impl_->name, {}, "a point to measure lies too far from this mesh for its float index");
  const Vec3f pf = scaled.cast<float>();
  query.margin = (pf.cast<double>() - scaled).norm() +
                 1e-6 * (impl_->coordinate_scale * scale + scaled.cwiseAbs().maxCoeff());
  RTCPointQuery embree_query;
  embree_query.x = pf.x();
  embree_query.y = pf.y();
  embree_query.z = pf.z();
  embree_query.time = 0;
  embree_query.radius = upper_bound < std::numeric_limits<double>::infinity()
                            ? culling_radius(upper_bound * scale, query.margin)
                            : std::numeric_limits<float>::infinity();
  RTCPointQueryContext context;
  rtcInitPointQueryContext(&context);
  rtcPointQuery(impl_->scene, &embree_query, &context, visit_triangle, &query);
  return query.best;
}

namespace {

// splitmix64's output function (Steele, Lea & Flood 2014): a bijective 64-bit mixer. The stream for a seed
// is mix(key + n * golden), so any sample's numbers can be computed from its index alone.
std::uint64_t mix(std::uint64_t x) {
  x ^= x >> 30;
  x *= 0xbf58476d1ce4e5b9ULL;
  x ^= x >> 27;
  x *= 0x94d049bb133111ebULL;
  return x ^ (x >> 31);
}

constexpr std::uint64_t golden = 0x9e3779b97f4a7c15ULL;

// Uniform in [0, 1), 53 random bits; `k` picks one of the three numbers a sample uses.
double uniform(std::uint64_t key, std::uint64_t sample, std::uint64_t k) {
  return double(mix(key + (3 * sample + k + 1) * golden) >> 11) * 0x1.0p-53;
}

}  // namespace

void DistanceIndex::Impl::area_samples(std::size_t count, std::uint64_t seed, std::size_t first,
                                       std::size_t last, Vec3d* out) const {
  if (first >= last) return;
  const std::uint64_t key = mix(seed ^ 0x6f6373696d70ULL);
  const double total = total_area();
  const std::size_t end = triangle_count;  // cumulative_area[end] == total
  auto position = [&](std::size_t i) { return (double(i) + uniform(key, i, 0)) / double(count) * total; };
  // Positions grow with i, so the triangle search gallops forward from the previous sample's triangle.
  double x = position(first);
  std::size_t f = std::size_t(std::upper_bound(cumulative_area.begin(), cumulative_area.end(), x) -
                              cumulative_area.begin()) -
                  1;
  for (std::size_t i = first; i < last; ++i) {
    if (i != first) {
      x = position(i);
      std::size_t lo = f, hi = f + 1, step = 1;
      while (hi <= end && cumulative_area[hi] <= x) {
        lo = hi;
        step *= 2;
        hi = lo + step;
      }
      hi = std::min(hi, end + 1);
      while (hi - lo > 1) {
        const std::size_t mid = lo + (hi - lo) / 2;
        (cumulative_area[mid] <= x ? lo : hi) = mid;
      }
      f = lo;
    }
    // cumulative_area[f] <= x < cumulative_area[f + 1] gives a triangle of positive area; only rounding at
    // the very end (x == total) lands past the last one.
    const std::size_t triangle = std::min(f, last_sampled_triangle);
    const Index* t = corners + 3 * triangle;
    const double r = std::sqrt(uniform(key, i, 1)), w = uniform(key, i, 2);
    out[i - first] = (1 - r) * vertex(t[0]) + (r * (1 - w)) * vertex(t[1]) + (r * w) * vertex(t[2]);
  }
}

std::vector<Vec3d> DistanceIndex::sample_surface(std::size_t count, std::uint64_t seed) const {
  if (!(impl_->total_area() > 0)) return {};
  std::vector<Vec3d> samples(count);
  impl_->area_samples(count, seed, 0, count, samples.data());
  return samples;
}

}  // namespace ocsimp
