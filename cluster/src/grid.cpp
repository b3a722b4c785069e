#include "grid.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>

#include "ocsimp/core/error.h"

namespace ocsimp::cluster_detail {
namespace {

void check_finite(const Box3& bounds) {
  if (bounds.empty()) return;
  for (int a = 0; a < 3; ++a) {
    if (!std::isfinite(bounds.lo[a]) || !std::isfinite(bounds.hi[a])) {
      throw Error("the input has non-finite vertex coordinates");
    }
  }
}

double longest(const Box3& bounds) {
  const Vec3d e = bounds.extent();
  return std::max(e.x(), std::max(e.y(), e.z()));
}

// Cells per axis for cubes of `cell`, at least 1 and at most `cap`.
Grid make(const Box3& bounds, double cell, std::uint32_t cap) {
  Grid grid;
  grid.origin = bounds.empty() ? Vec3d::Zero() : bounds.lo;
  grid.cell = cell;
  grid.inverse_cell = 1.0 / cell;
  const Vec3d e = bounds.extent();
  for (int a = 0; a < 3; ++a) {
    const double n = std::ceil(e[a] / cell);
    grid.dims[a] = n >= cap ? cap : std::max<std::uint32_t>(1, static_cast<std::uint32_t>(n));
  }
  grid.along_longest = std::max(grid.dims[0], std::max(grid.dims[1], grid.dims[2]));
  return grid;
}

}  // namespace

Grid Grid::uniform(const Box3& bounds, std::uint32_t cells) {
  check_finite(bounds);
  if (cells == 0 || cells > kMaxCellsPerAxis) {
    throw Error("grid resolution must be 1 .. " + std::to_string(kMaxCellsPerAxis) + " cells, not " +
                std::to_string(cells));
  }
  const double length = longest(bounds);
  // A box of one point: any cell size puts everything in one cell.
  if (!(length > 0.0)) return make(bounds, 1.0, 1);
  return make(bounds, length / cells, cells);
}

Grid Grid::sized(const Box3& bounds, double size, const std::string& file) {
  check_finite(bounds);
  if (!(size > 0.0) || !std::isfinite(size)) throw Error("cell size must be a positive number");
  const double length = longest(bounds);
  if (length / size > static_cast<double>(kMaxCellsPerAxis)) {
    // The smallest size, rounded up to three digits: printed to %g's six, it could read the same as a
    // refused size just below it, and typed back in it could fall short again.
    const double smallest = length / static_cast<double>(kMaxCellsPerAxis);
    const double unit = std::pow(10.0, std::floor(std::log10(smallest)) - 2);
    const double shown = std::ceil(smallest / unit * (1 + 1e-12)) * unit;
    // %g: std::to_string's fixed six decimals print a small cell size as 0.000000.
    char text[160];
    std::snprintf(
        text, sizeof text,
        "cell size %g gives more than %u cells along the longest axis (%g long); the smallest is %.3g", size,
        static_cast<unsigned>(kMaxCellsPerAxis), length, shown);
    throw Error(file, {}, text);
  }
  return make(bounds, size, kMaxCellsPerAxis);
}

Grid Grid::power_of_two(const Box3& bounds, int level) {
  check_finite(bounds);
  level = std::clamp(level, 0, kCoordBits);
  const std::uint32_t cells = 1u << level;
  const double length = longest(bounds);
  Grid grid = length > 0.0 ? make(bounds, length / cells, cells) : make(bounds, 1.0, 1);
  grid.along_longest = cells;
  grid.level = level;
  return grid;
}

Grid Grid::coarser() const {
  Grid grid = *this;
  // Doubling and halving are exact, so a point lands in the parent of the cell it landed in before.
  grid.cell = 2 * cell;
  grid.inverse_cell = 0.5 * inverse_cell;
  for (int a = 0; a < 3; ++a) grid.dims[a] = (dims[a] + 1) / 2;
  grid.along_longest = std::max<std::uint32_t>(1, (along_longest + 1) / 2);
  if (level > 0) grid.level = level - 1;
  return grid;
}

}  // namespace ocsimp::cluster_detail
