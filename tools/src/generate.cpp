#include "ocsimp/tools/generate.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <vector>

#include "ocsimp/core/error.h"
#include "ocsimp/core/system.h"
#include "ocsimp/streaming/io.h"
#include "ocsimp/streaming/ply_writer.h"

namespace ocsimp {
namespace {

// SplitMix64: a tiny, well-mixed hash; all randomness is a function of (seed, purpose, index).
std::uint64_t mix(std::uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}
double unit(std::uint64_t h) {
  return static_cast<double>(h >> 11) * 0x1.0p-53;
}  // [0, 1)

// A hole: the lattice points strictly inside a rectangle of cells on one face of the cube, described in
// vertex index space as `rows` runs of `run_length` consecutive indices, `stride` apart. Removing them keeps
// every other vertex's index computable in O(holes) without any table, so memory stays constant.
struct Hole {
  int axis = 0, side = 0;       // the cube face
  std::int64_t i0, i1, j0, j1;  // cell rectangle [i0, i1) x [j0, j1) in the face's (u, v) lattice coordinates
  std::uint64_t base = 0, stride = 0, run_start = 0, run_length = 0, rows = 0;

  std::uint64_t removed_before(std::uint64_t local) const {
    if (local < base) return 0;
    const std::uint64_t rel = local - base;
    const std::uint64_t row = rel / stride;
    if (row >= rows) return rows * run_length;
    const std::uint64_t column = rel % stride;
    return row * run_length + std::min(run_length, column > run_start ? column - run_start : 0);
  }
  bool contains_cell(int face_axis, int face_side, std::int64_t i, std::int64_t j) const {
    return face_axis == axis && face_side == side && i >= i0 && i < i1 && j >= j0 && j < j1;
  }
};

struct Component {
  Vec3d center;
  std::vector<Hole> holes;  // ordered by base
  // Displacement: a sum of sines of the direction along random axes, amplitude falling with frequency.
  std::array<Vec3d, 7> axes;
  std::array<double, 7> frequency, amplitude, phase;
};

class ScanSurface {
 public:
  explicit ScanSurface(const GenerateOptions& options) : options_(options) {
    if (options.components < 1 || options.components > 1000)
      throw Error("the component count must be in 1..1000");
    if (options.holes < 0 || options.holes > 6)
      throw Error("the hole count must be in 0..6 (one per cube face)");
    // Beyond 1e9 a double's spacing (1.2e-7 there) reaches the finest lattice's detail: at 1e15 a blob had 18
    // distinct x values. Georeferenced frames stay far below (UTM northings 1e7, geocentric 6.4e6).
    if (!options.offset.allFinite() || options.offset.cwiseAbs().maxCoeff() > kMostOffset)
      throw Error(
          "the offset must be finite, each coordinate within 1e9 of zero (farther, doubles cannot hold the "
          "mesh's detail)");
    if (!(options.noise >= 0.0) || options.noise > 10.0) throw Error("the noise must be in 0..10");
    const double per_component = static_cast<double>(options.triangles) / options.components;
    n_ = std::max<std::uint64_t>(static_cast<std::uint64_t>(std::llround(std::sqrt(per_component / 12.0))),
                                 options.holes > 0 ? 12 : 1);
    if (n_ > 100'000) throw Error("too many triangles (at most 1.2e11 per component)");
    layer_ = (n_ + 1) * (n_ + 1);
    ring_ = 4 * n_;
    vertices_per_component_ = 6 * n_ * n_ + 2;
    edge_ = 0.5 * std::numbers::pi / static_cast<double>(n_);
    for (int c = 0; c < options.components; ++c) components_.push_back(make_component(c));
  }

  std::uint64_t lattice() const { return n_; }
  std::uint64_t vertex_count() const {
    std::uint64_t total = 0;
    for (const Component& c : components_) {
      total += vertices_per_component_;
      for (const Hole& h : c.holes) total -= h.rows * h.run_length;
    }
    return total;
  }
  std::uint64_t face_slots() const { return components_.size() * 12 * n_ * n_; }
  std::uint64_t face_count() const {
    std::uint64_t total = face_slots();
    for (const Component& c : components_)
      for (const Hole& h : c.holes) total -= 2 * static_cast<std::uint64_t>((h.i1 - h.i0) * (h.j1 - h.j0));
    return total;
  }

  // Lattice vertex slots (including removed ones) are enumerated component by component; a removed slot
  // yields nothing. Returns false for a removed slot.
  bool vertex(std::uint64_t slot, Vec3f& position, Vec3f& normal, Color& color) const {
    const std::uint64_t c = slot / vertices_per_component_;
    const std::uint64_t local = slot % vertices_per_component_;
    const Component& component = components_[c];
    const auto q = lattice_point(local);
    for (const Hole& h : component.holes) {
      if (is_removed(h, q)) return false;
    }
    const Vec3d d = direction(q);
    const double noise = options_.noise * edge_ * (2.0 * unit(mix(options_.seed * 0x51ED27ull + slot)) - 1.0);
    const Vec3d p = component.center + (radius(component, d) + noise) * d;
    position = p.cast<float>();
    if (options_.normals) normal = smooth_normal(component, d).cast<float>();
    if (options_.colors) {
      auto channel = [](double v) {
        return static_cast<std::uint8_t>(std::clamp(127.5 + 127.5 * std::sin(v), 0.0, 255.0));
      };
      color = {channel(3 * p.x()), channel(3 * p.y() + 2), channel(3 * p.z() + 4), 255};
    }
    return true;
  }

  std::uint64_t vertex_slots() const { return components_.size() * vertices_per_component_; }

  // Face slot -> triangle (false when a hole removed it).
  bool face(std::uint64_t slot, Triangle& triangle) const {
    const std::uint64_t per_component = 12 * n_ * n_;
    const std::uint64_t c = slot / per_component;
    std::uint64_t rest = slot % per_component;
    const int face = static_cast<int>(rest / (2 * n_ * n_));
    rest %= 2 * n_ * n_;
    const std::int64_t cell = static_cast<std::int64_t>(rest / 2);
    const int half = static_cast<int>(rest % 2);
    const int axis = face / 2, side = face % 2;
    const std::int64_t i = cell % static_cast<std::int64_t>(n_), j = cell / static_cast<std::int64_t>(n_);
    const Component& component = components_[c];
    for (const Hole& h : component.holes) {
      if (h.contains_cell(axis, side, i, j)) return false;
    }
    const int u = (axis + 1) % 3, v = (axis + 2) % 3;
    auto corner = [&](std::int64_t di, std::int64_t dj) {
      std::array<std::int64_t, 3> q{};
      q[axis] = side * static_cast<std::int64_t>(n_);
      q[u] = i + di;
      q[v] = j + dj;
      return index_of(c, q);
    };
    const Index a = corner(0, 0), b = corner(1, 0), cc = corner(1, 1), d = corner(0, 1);
    // Alternate the diagonal like a scanner's grid triangulation does, so there is no preferred direction.
    const bool flip = ((i + j) & 1) != 0;
    std::array<Index, 3> t =
        flip ? (half == 0 ? std::array<Index, 3>{a, b, d} : std::array<Index, 3>{b, cc, d})
             : (half == 0 ? std::array<Index, 3>{a, b, cc} : std::array<Index, 3>{a, cc, d});
    if (side == 0) std::swap(t[1], t[2]);  // outward orientation on the low faces
    triangle = t;
    return true;
  }

 private:
  using Lattice = std::array<std::int64_t, 3>;

  Lattice lattice_point(std::uint64_t local) const {
    const std::int64_t n = static_cast<std::int64_t>(n_);
    if (local < layer_)
      return {static_cast<std::int64_t>(local % (n_ + 1)), static_cast<std::int64_t>(local / (n_ + 1)), 0};
    const std::uint64_t top = layer_ + (n_ - 1) * ring_;
    if (local >= top) {
      const std::uint64_t t = local - top;
      return {static_cast<std::int64_t>(t % (n_ + 1)), static_cast<std::int64_t>(t / (n_ + 1)), n};
    }
    const std::uint64_t m = local - layer_;
    const std::int64_t z = static_cast<std::int64_t>(m / ring_) + 1;
    const std::int64_t r = static_cast<std::int64_t>(m % ring_);
    if (r < n) return {r, 0, z};
    if (r < 2 * n) return {n, r - n, z};
    if (r < 3 * n) return {n - (r - 2 * n), n, z};
    return {0, n - (r - 3 * n), z};
  }

  std::uint64_t local_index(const Lattice& q) const {
    const std::int64_t n = static_cast<std::int64_t>(n_);
    const auto [x, y, z] = q;
    if (z == 0) return static_cast<std::uint64_t>(y * (n + 1) + x);
    if (z == n) return layer_ + (n_ - 1) * ring_ + static_cast<std::uint64_t>(y * (n + 1) + x);
    std::int64_t r;
    if (y == 0 && x < n)
      r = x;
    else if (x == n && y < n)
      r = n + y;
    else if (y == n && x > 0)
      r = 2 * n + (n - x);
    else
      r = 3 * n + (n - y);
    return layer_ + static_cast<std::uint64_t>(z - 1) * ring_ + static_cast<std::uint64_t>(r);
  }

  Index index_of(std::uint64_t c, const Lattice& q) const {
    const std::uint64_t local = local_index(q);
    std::uint64_t removed = 0;
    for (const Hole& h : components_[c].holes) removed += h.removed_before(local);
    return static_cast<Index>(first_vertex_[c] + local - removed);
  }

  bool is_removed(const Hole& h, const Lattice& q) const {
    const int u = (h.axis + 1) % 3, v = (h.axis + 2) % 3;
    return q[h.axis] == h.side * static_cast<std::int64_t>(n_) && q[u] > h.i0 && q[u] < h.i1 && q[v] > h.j0 &&
           q[v] < h.j1;
  }

  Vec3d direction(const Lattice& q) const {
    // Equi-angular cube map: tan() spreads the lattice evenly over the sphere.
    Vec3d c;
    for (int k = 0; k < 3; ++k) {
      c[k] = std::tan(0.25 * std::numbers::pi *
                      (2.0 * static_cast<double>(q[k]) / static_cast<double>(n_) - 1.0));
    }
    return c.normalized();
  }

  static double radius(const Component& component, const Vec3d& d) {
    double r = 1.0;
    for (std::size_t k = 0; k < component.axes.size(); ++k) {
      r += component.amplitude[k] *
           std::sin(component.frequency[k] * d.dot(component.axes[k]) + component.phase[k]);
    }
    return r;
  }

  static Vec3d smooth_normal(const Component& component, const Vec3d& d) {
    const Vec3d t1 = (std::abs(d.x()) < 0.9 ? Vec3d::UnitX() : Vec3d::UnitY()).cross(d).normalized();
    const Vec3d t2 = d.cross(t1);
    const double h = 1e-5;
    auto point = [&](const Vec3d& dir) -> Vec3d {
      return radius(component, dir.normalized()) * dir.normalized();
    };
    const Vec3d n = (point(d + h * t1) - point(d - h * t1)).cross(point(d + h * t2) - point(d - h * t2));
    return n.normalized();
  }

  Component make_component(int c) const {
    Component component;
    const std::uint64_t key = mix(options_.seed) ^ mix(0xC0FFEEull + static_cast<std::uint64_t>(c));
    component.center = Vec3d(3.0 * c, 0.0, 0.0);
    const std::array<double, 7> base_frequency = {2.0, 3.5, 6.0, 10.0, 17.0, 29.0, 50.0};
    for (std::size_t k = 0; k < component.axes.size(); ++k) {
      const std::uint64_t h = mix(key + 17 * k);
      const double z = 2.0 * unit(mix(h + 1)) - 1.0, phi = 2.0 * std::numbers::pi * unit(mix(h + 2));
      const double s = std::sqrt(std::max(0.0, 1.0 - z * z));
      component.axes[k] = Vec3d(s * std::cos(phi), s * std::sin(phi), z);
      component.frequency[k] = base_frequency[k] * (0.8 + 0.4 * unit(mix(h + 3)));
      // Amplitude ~ 1/f^1.2: large smooth lobes with finer wrinkles, always keeping the radius positive.
      component.amplitude[k] = 0.28 / std::pow(component.frequency[k], 1.2);
      component.phase[k] = 2.0 * std::numbers::pi * unit(mix(h + 4));
    }
    const std::int64_t n = static_cast<std::int64_t>(n_);
    for (int k = 0; k < options_.holes; ++k) {
      Hole h;
      h.axis = k % 3;
      h.side = (k / 3) % 2;
      const std::uint64_t r = mix(key + 1000 + static_cast<std::uint64_t>(k));
      // Square-ish block of cells, 1/8 to 1/4 of the face wide, kept 1/8 of the face away from its edges.
      const std::int64_t w =
          std::max<std::int64_t>(2, n / 8 + static_cast<std::int64_t>(unit(mix(r + 1)) * (n / 8)));
      const std::int64_t margin = std::max<std::int64_t>(1, n / 8);
      const std::int64_t span = std::max<std::int64_t>(1, n - 2 * margin - w);
      h.i0 = margin + static_cast<std::int64_t>(unit(mix(r + 2)) * static_cast<double>(span));
      h.j0 = margin + static_cast<std::int64_t>(unit(mix(r + 3)) * static_cast<double>(span));
      h.i1 = h.i0 + w;
      h.j1 = h.j0 + w;
      describe_runs(h);
      component.holes.push_back(h);
    }
    std::sort(component.holes.begin(), component.holes.end(),
              [](const Hole& a, const Hole& b) { return a.base < b.base; });
    return component;
  }

  // Translates a hole's cell rectangle into runs of vertex indices (see local_index's layout).
  void describe_runs(Hole& h) const {
    const std::uint64_t n = n_;
    const std::uint64_t i_first = static_cast<std::uint64_t>(h.i0 + 1),
                        i_count = static_cast<std::uint64_t>(h.i1 - h.i0 - 1);
    const std::uint64_t j_first = static_cast<std::uint64_t>(h.j0 + 1),
                        j_count = static_cast<std::uint64_t>(h.j1 - h.j0 - 1);
    if (h.axis == 2) {
      // z faces: u = x, v = y; full (n+1)^2 layers, rows are y.
      h.base = (h.side == 0 ? 0 : layer_ + (n - 1) * ring_) + j_first * (n + 1);
      h.stride = n + 1;
      h.run_start = i_first;
      h.run_length = i_count;
      h.rows = j_count;
    } else if (h.axis == 0) {
      // x faces: u = y, v = z; one run per middle layer z, at ring position n + y (x = n) or 3n + (n - y) (x
      // = 0).
      h.base = layer_ + (j_first - 1) * ring_;
      h.stride = ring_;
      h.run_start = h.side == 1 ? n + i_first : 3 * n + (n - (i_first + i_count - 1));
      h.run_length = i_count;
      h.rows = j_count;
    } else {
      // y faces: u = z, v = x; one run per middle layer z = u, at ring position x (y = 0) or 2n + (n - x) (y
      // = n).
      h.base = layer_ + (i_first - 1) * ring_;
      h.stride = ring_;
      h.run_start = h.side == 0 ? j_first : 2 * n + (n - (j_first + j_count - 1));
      h.run_length = j_count;
      h.rows = i_count;
    }
  }

 public:
  void finish_layout() {
    first_vertex_.assign(components_.size(), 0);
    std::uint64_t next = 0;
    for (std::size_t c = 0; c < components_.size(); ++c) {
      first_vertex_[c] = next;
      next += vertices_per_component_;
      for (const Hole& h : components_[c].holes) next -= h.rows * h.run_length;
    }
    if (next > std::numeric_limits<Index>::max())
      throw Error("too many triangles: more than 2^32-1 vertices");
  }

 private:
  GenerateOptions options_;
  std::uint64_t n_ = 1, layer_ = 4, ring_ = 4, vertices_per_component_ = 8;
  double edge_ = 1.0;
  std::vector<Component> components_;
  std::vector<std::uint64_t> first_vertex_;
};

// Produces items [0, count) in parallel blocks and hands them to `sink` in index order, so the output does
// not depend on the thread count. `make(slot, item)` returns false for a slot that yields nothing.
template <class Item, class Make, class Sink>
void produce_in_order(std::uint64_t count, int threads, Make make, Sink sink) {
  constexpr std::uint64_t kBlock = 1 << 16;
  const std::uint64_t blocks_per_round = 64;
  std::vector<std::vector<Item>> buffers(blocks_per_round);
  tbb::task_arena arena(worker_threads(threads));
  for (std::uint64_t start = 0; start < count; start += kBlock * blocks_per_round) {
    const std::uint64_t round_end = std::min(count, start + kBlock * blocks_per_round);
    const std::uint64_t blocks = (round_end - start + kBlock - 1) / kBlock;
    arena.execute([&] {
      tbb::parallel_for(std::uint64_t{0}, blocks, [&](std::uint64_t b) {
        std::vector<Item>& out = buffers[b];
        out.clear();
        const std::uint64_t begin = start + b * kBlock, end = std::min(round_end, begin + kBlock);
        Item item;
        for (std::uint64_t slot = begin; slot < end; ++slot) {
          if (make(slot, item)) out.push_back(item);
        }
      });
    });
    for (std::uint64_t b = 0; b < blocks; ++b) sink(buffers[b]);
  }
}

struct GeneratedVertex {
  Vec3f position;
  Vec3f normal;
  Color color;
};

template <class VertexSink, class FaceSink>
GeneratedCounts generate(const GenerateOptions& options, VertexSink on_vertices, FaceSink on_faces) {
  ScanSurface surface(options);
  surface.finish_layout();
  GeneratedCounts counts{surface.lattice(), surface.vertex_count(), surface.face_count()};
  produce_in_order<GeneratedVertex>(
      surface.vertex_slots(), options.threads,
      [&](std::uint64_t slot, GeneratedVertex& v) {
        return surface.vertex(slot, v.position, v.normal, v.color);
      },
      on_vertices);
  std::uint64_t faces_done = 0;
  produce_in_order<Triangle>(
      surface.face_slots(), options.threads,
      [&](std::uint64_t slot, Triangle& t) { return surface.face(slot, t); },
      [&](const std::vector<Triangle>& block) {
        on_faces(block);
        faces_done += block.size();
        report(options.progress, "generate", faces_done, counts.faces);
      });
  return counts;
}

}  // namespace

GeneratedCounts generated_counts(const GenerateOptions& options) {
  ScanSurface surface(options);
  surface.finish_layout();
  return {surface.lattice(), surface.vertex_count(), surface.face_count()};
}

GeneratedCounts generate_scan_ply(const std::string& path, const GenerateOptions& options) {
  // Other names got PLY bytes that every reader then took for their own format and refused.
  if (format_from_extension(path) != FileFormat::ply)
    throw Error(path, {}, "the generator writes PLY: name the file .ply");
  const GeneratedCounts expected = generated_counts(options);
  PlyLayout layout;
  layout.vertices = expected.vertices;
  layout.faces = expected.faces;
  layout.normals = options.normals;
  layout.colors = options.colors;
  layout.ascii = options.ascii;
  layout.origin = options.offset;
  PlyStreamWriter writer(path, layout);
  const GeneratedCounts counts = generate(
      options,
      [&](const std::vector<GeneratedVertex>& block) {
        for (const GeneratedVertex& v : block) {
          writer.add_vertex(v.position, options.normals ? &v.normal : nullptr,
                            options.colors ? &v.color : nullptr);
        }
      },
      [&](const std::vector<Triangle>& block) {
        for (const Triangle& t : block) writer.add_face(t);
      });
  writer.finish();
  return counts;
}

IndexedMesh generate_scan_mesh(const GenerateOptions& options) {
  const GeneratedCounts expected = generated_counts(options);
  if (expected.faces > 200'000'000)
    throw Error("generate_scan_mesh: too large for memory; stream it to a file");
  IndexedMesh mesh;
  mesh.origin = options.offset;
  mesh.positions.reserve(expected.vertices);
  mesh.triangles.reserve(expected.faces);
  generate(
      options,
      [&](const std::vector<GeneratedVertex>& block) {
        for (const GeneratedVertex& v : block) {
          mesh.positions.push_back(v.position);
          if (options.normals) mesh.normals.push_back(v.normal);
          if (options.colors) mesh.colors.push_back(v.color);
        }
      },
      [&](const std::vector<Triangle>& block) {
        mesh.triangles.insert(mesh.triangles.end(), block.begin(), block.end());
      });
  return mesh;
}

}  // namespace ocsimp
