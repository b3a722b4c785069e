#include "origin_sample.h"

namespace ocsimp::detail {

void fail_beyond_float_range(const std::string& path, FilePosition where, std::uint64_t number) {
  throw Error(path, where,
              "vertex " + std::to_string(number) +
                  " lies beyond the float range (+-3.4e38) from the other vertices, whose positions are held "
                  "relative to their median");
}

Vec3d OriginSample::settle(const std::string& path, std::uint64_t first_number, std::vector<Vec3f>& positions,
                           Box3& bounds) {
  std::vector<Vec3d> first(held.size());
  for (std::size_t i = 0; i < held.size(); ++i) first[i] = held[i].read;
  const Vec3d origin = far_origin(std::move(first));
  for (std::size_t i = 0; i < held.size(); ++i) {
    if (origin != Vec3d::Zero())
      positions[i] = float_offset(held[i].read, origin, path, held[i].where, first_number + i);
    bounds.add(positions[i]);
  }
  held = {};
  settled = true;
  return origin;
}

}  // namespace ocsimp::detail
