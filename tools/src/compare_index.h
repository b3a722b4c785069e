// The inside of DistanceIndex, shared by compare_index.cpp (building, querying, sampling) and compare.cpp
// (measuring). Not a public header.
#pragma once

#include <embree3/rtcore.h>

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "ocsimp/tools/compare.h"

namespace ocsimp {

struct DistanceIndex::Impl {
  std::string name;
  RTCDevice device = nullptr;
  RTCScene scene = nullptr;
  std::string device_error;  // the last message Embree reported, for exceptions

  // The mesh, in the buffers Embree allocated for it (vertex buffers padded for its 16-byte loads).
  const float* positions = nullptr;  // 3 a vertex
  const Index* corners = nullptr;    // 3 a triangle, every triangle of the mesh (what samples are drawn on)
  std::size_t vertex_count = 0;
  std::size_t triangle_count = 0;
  // What the BVH holds: the same triangles, less exact repeats (see DistanceIndex's constructor), whose
  // ids then map back through `triangle_of_primitive`; `corners` is then `all_corners`.
  const Index* primitive_corners = nullptr;
  std::vector<Index> triangle_of_primitive;  // ascending; empty when every triangle is a primitive
  std::vector<Index> all_corners;

  std::vector<double> cumulative_area;     // triangle_count + 1 entries, from 0 to the total area
  std::size_t last_sampled_triangle = 0;   // the last triangle of positive area
  std::vector<Index> referenced_vertices;  // ascending
  Box3 bounds;
  Vec3d origin = Vec3d::Zero();  // DistanceIndex::origin(): positions are relative to it
  double coordinate_scale = 0;   // largest absolute coordinate: sizes the margin for Embree's float culling
  // A power of two: Embree's buffer holds the positions times `embree_scale` (exactly), and queries are
  // scaled alike, whenever the coordinates are so small or large that Embree's float arithmetic would
  // underflow or overflow (squared distances of a mesh 1e-30 across are 0 in float, and then nothing is
  // culled: 320 faces took 9 s; beyond about 1.8e18 Embree ignores a query). 1 for everyday units.
  double embree_scale = 1;

  Impl() = default;
  Impl(const Impl&) = delete;
  Impl& operator=(const Impl&) = delete;
  ~Impl();

  Vec3d vertex(Index v) const {
    const float* p = positions + 3 * std::size_t{v};
    return Vec3d(double(p[0]), double(p[1]), double(p[2])) / embree_scale;
  }
  double total_area() const { return cumulative_area.back(); }

  // Area samples [first, last) of the `count` stratified samples drawn with `seed`, written to `out`.
  void area_samples(std::size_t count, std::uint64_t seed, std::size_t first, std::size_t last,
                    Vec3d* out) const;
};

}  // namespace ocsimp
