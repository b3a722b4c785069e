// STL: a triangle soup, binary or ASCII. The reader streams corner positions (read_mesh welds them); bounds()
// costs one extra pass over the file on a second reader, leaving the stream where it was.
//
// Binary: an 80-byte header, a little-endian uint32 triangle count, then 50 bytes a triangle (normal, three
// corners, a 16-bit attribute). The count must fit in the file; bytes after the last triangle are ignored.
// ASCII: solid / facet normal / outer loop / vertex x3 / endloop / endfacet / endsolid, keywords in any case
// and any blank spacing, several solids in one file. Facet normals are ignored in both forms (writers often
// put NaN there for degenerate facets); corner coordinates must be finite numbers.
#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstring>
#include <functional>
#include <limits>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "byte_reader.h"
#include "formats.h"
#include "ocsimp/core/error.h"
#include "ocsimp/streaming/atomic_file.h"
#include "text_io.h"

namespace ocsimp::detail {
namespace {

static_assert(std::endian::native == std::endian::little, "binary STL is read and written by memcpy");

constexpr std::size_t kHeaderBytes = 80;
constexpr std::size_t kTriangleBytes = 50;
constexpr std::uint64_t kProgressStep = 8u << 20;

using Corners = std::array<Vec3f, 3>;

// Whether `head` begins with "solid", in any case, after a UTF-8 byte order mark and blanks.
bool begins_with_solid(std::string_view head) {
  const std::size_t bom = head.starts_with("\xEF\xBB\xBF") ? 3 : 0;
  const std::size_t first = head.find_first_not_of(" \t\r\n", bom);
  if (first == std::string_view::npos || head.size() < first + 5) return false;
  for (std::size_t i = 0; i < 5; ++i) {
    if ((head[first + i] | 0x20) != "solid"[i]) return false;
  }
  return true;
}

// The first byte of `head` that is no text (a control character other than a blank), or npos.
std::size_t first_non_text(std::string_view head) {
  for (std::size_t i = 0; i < head.size(); ++i) {
    const auto u = static_cast<unsigned char>(head[i]);
    if (u < 0x20 && u != '\n' && u != '\r' && u != '\t' && u != '\v' && u != '\f') return i;
  }
  return std::string_view::npos;
}

// Binary unless the file starts with "solid" followed by text only: binary headers often say "solid" too, but
// their count and float bytes give them away within the first few hundred bytes.
bool looks_ascii(ByteReader& reader) {
  const std::size_t n = reader.fill(512);
  const std::string_view head(reader.data(), n);
  if (!begins_with_solid(head)) return false;
  if (n >= kHeaderBytes + 4 && reader.file_size() >= kHeaderBytes + 4) {
    std::uint32_t count;
    std::memcpy(&count, reader.data() + kHeaderBytes, 4);
    if (kHeaderBytes + 4 + kTriangleBytes * std::uint64_t(count) == reader.file_size()) return false;
  }
  return first_non_text(head) == std::string_view::npos;
}

// For a file taken as binary whose count then fails: when it begins with "solid", which byte was not text
// (an ASCII STL with a NUL in its name read as a bad binary count, which pointed the wrong way).
std::string ascii_lookalike(ByteReader& reader) {
  const std::size_t n = reader.fill(512);
  const std::string_view head(reader.data(), n);
  const std::size_t at = begins_with_solid(head) ? first_non_text(head) : std::string_view::npos;
  return at == std::string_view::npos
             ? ""
             : "; it begins like an ASCII STL, but byte " + std::to_string(at) + " is not text";
}

class BinaryStlParser {
 public:
  // `warn`: told when the count in the header is below what the file holds (see below); may be empty.
  BinaryStlParser(const std::string& path, const std::function<void(const std::string&)>& warn)
      : reader_(path) {
    if (reader_.file_size() < kHeaderBytes + 4)
      throw Error(
          path, FilePosition::byte(reader_.file_size()),
          "binary STL shorter than its 84-byte header (" + std::to_string(reader_.file_size()) + " bytes)");
    reader_.fill(kHeaderBytes + 4);
    std::uint32_t count;
    std::memcpy(&count, reader_.data() + kHeaderBytes, 4);
    const std::uint64_t needed = kHeaderBytes + 4 + kTriangleBytes * std::uint64_t(count);
    if (needed > reader_.file_size())
      throw Error(path, FilePosition::byte(kHeaderBytes),
                  "binary STL header claims " + counted(count, "triangle") + " (" + std::to_string(needed) +
                      " bytes) but the file has " + std::to_string(reader_.file_size()) + " bytes" +
                      ascii_lookalike(reader_));
    reader_.consume(kHeaderBytes + 4);
    if (needed < reader_.file_size()) {
      // Writers that stream their triangles sometimes leave the count at 0, or at a first batch's: when
      // whole triangles follow, they are read, and the run says so (an STL whose header said 0 read as
      // empty, without a word). Other trailing bytes (padding) are left alone, as before, and named.
      const std::uint64_t extra = reader_.file_size() - needed;
      const std::uint64_t held = (reader_.file_size() - kHeaderBytes - 4) / kTriangleBytes;
      if (extra % kTriangleBytes == 0) {
        // The count is 32 bits: past 2^32 - 1 triangles (214 GB) the rest stays unread, as the format allows.
        const auto read = static_cast<std::uint32_t>(
            std::min<std::uint64_t>(held, std::numeric_limits<std::uint32_t>::max()));
        if (warn)
          warn("the binary STL header claims " + counted(count, "triangle") + ", but the file holds " +
               std::to_string(held) + "; " + (read == held ? "all " : "the first ") + std::to_string(read) +
               " are read");
        count = read;
      } else if (warn) {
        warn("the " + counted(extra, "byte") + " after the " + counted(count, "triangle") +
             " the binary STL header claims (byte " + std::to_string(needed) +
             " on) are not whole triangles, and are ignored");
      }
    }
    remaining_ = count;
    total_ = count;
  }

  // Up to `max` triangles appended to `out`; false once none are left.
  bool read(std::vector<Corners>& out, std::size_t max) {
    if (remaining_ == 0) return false;
    const std::size_t per_fill = reader_.capacity() / kTriangleBytes;
    while (remaining_ > 0 && max > 0) {
      const std::size_t k = static_cast<std::size_t>(std::min<std::uint64_t>({remaining_, max, per_fill}));
      reader_.fill(k * kTriangleBytes);  // the size check in the constructor guarantees the bytes are there
      if (reader_.available() < k * kTriangleBytes)
        throw Error(reader_.path(), FilePosition::byte(reader_.offset() + reader_.available()),
                    "file shrank while being read");
      const char* p = reader_.data();
      for (std::size_t t = 0; t < k; ++t, p += kTriangleBytes) {
        float xyz[9];
        std::memcpy(xyz, p + 12, sizeof xyz);
        for (int i = 0; i < 9; ++i) {
          if (!std::isfinite(xyz[i]))
            throw Error(reader_.path(),
                        FilePosition::byte(reader_.offset() + std::uint64_t(p - reader_.data()) + 12 + 4 * i),
                        "NaN or infinite corner coordinate");
        }
        out.push_back(
            {Vec3f(xyz[0], xyz[1], xyz[2]), Vec3f(xyz[3], xyz[4], xyz[5]), Vec3f(xyz[6], xyz[7], xyz[8])});
      }
      reader_.consume(k * kTriangleBytes);
      remaining_ -= k;
      max -= k;
    }
    return true;
  }

  std::uint64_t triangles() const { return total_; }
  const ByteReader& reader() const { return reader_; }

 private:
  ByteReader reader_;
  std::uint64_t remaining_ = 0;
  std::uint64_t total_ = 0;
};

class AsciiStlParser {
 public:
  explicit AsciiStlParser(const std::string& path) : reader_(path), lines_(reader_) {}

  // Up to `max` triangles appended to `out` (a facet with more than three vertices is fanned, and what
  // does not fit waits for the next call); false once the file is done.
  bool read(std::vector<Corners>& out, std::size_t max) {
    const std::size_t start = out.size();
    auto drain_fan = [&] {
      for (; fan_next_ != 0 && out.size() - start < max; ++fan_next_) {
        if (fan_next_ + 1 >= loop_.size()) {
          fan_next_ = 0;
          break;
        }
        out.push_back({loop_[0], loop_[fan_next_], loop_[fan_next_ + 1]});
      }
    };
    drain_fan();
    std::string_view line;
    while (out.size() - start < max && lines_.next(line)) {
      const char* end = line.data() + line.size();
      const char* p = skip_blanks(line.data(), end);
      const char* e = token_end(p, end);
      if (p == e) continue;
      const std::string_view keyword(p, static_cast<std::size_t>(e - p));
      switch (state_) {
        case State::outside:
          if (!is(keyword, "solid")) fail("expected 'solid', found " + quote_token(p, end));
          state_ = State::in_solid;
          break;
        case State::in_solid:
          if (is(keyword, "facet")) {
            state_ = State::in_facet;
          } else if (is(keyword, "endsolid")) {
            state_ = State::outside;
          } else {
            fail("expected 'facet' or 'endsolid', found " + quote_token(p, end));
          }
          break;
        case State::in_facet:
          if (!is(keyword, "outer") || !is(first_token(e, end), "loop"))
            fail("expected 'outer loop', found " + quote_token(p, end));
          state_ = State::in_loop;
          loop_.clear();
          break;
        case State::in_loop:
          if (is(keyword, "vertex")) {
            add_vertex(e, end);
          } else if (is(keyword, "endloop")) {
            if (loop_.size() < 3)
              fail("a facet needs 3 vertices (found " + std::to_string(loop_.size()) + ")");
            fan_next_ = 1;
            drain_fan();
            state_ = State::after_loop;
          } else {
            fail("expected 'vertex' or 'endloop', found " + quote_token(p, end));
          }
          break;
        case State::after_loop:
          if (!is(keyword, "endfacet")) fail("expected 'endfacet', found " + quote_token(p, end));
          state_ = State::in_solid;
          break;
      }
    }
    if (out.size() > start) return true;
    // A file cut short between two facets reads like a complete one but for its missing "endsolid": without
    // it, a truncated copy was taken for the whole mesh.
    if (state_ == State::in_solid) {
      throw Error(reader_.path(), FilePosition::line(lines_.line_number()),
                  "the file ends before 'endsolid' (cut short?)");
    }
    if (state_ != State::outside)
      throw Error(reader_.path(), FilePosition::line(lines_.line_number()), "the file ends inside a facet");
    return false;
  }

  const ByteReader& reader() const { return reader_; }

 private:
  enum class State { outside, in_solid, in_facet, in_loop, after_loop };

  [[noreturn]] void fail(const std::string& reason) const {
    throw Error(reader_.path(), FilePosition::line(lines_.line_number()), reason);
  }

  static bool is(std::string_view token, std::string_view keyword) {
    if (token.size() != keyword.size()) return false;
    for (std::size_t i = 0; i < token.size(); ++i) {
      const char c = token[i];
      if ((c >= 'A' && c <= 'Z' ? char(c - 'A' + 'a') : c) != keyword[i]) return false;
    }
    return true;
  }

  static std::string_view first_token(const char* p, const char* end) {
    p = skip_blanks(p, end);
    return std::string_view(p, static_cast<std::size_t>(token_end(p, end) - p));
  }

  void add_vertex(const char* p, const char* end) {
    float xyz[3];
    for (float& value : xyz) {
      const NumberStatus status = parse_number(p, end, value);
      if (status != NumberStatus::ok) fail("vertex: " + describe(status, p, end));
    }
    if (skip_blanks(p, end) != end) fail("vertex: unexpected " + quote_token(p, end) + " after x y z");
    // A loop is a handful of vertices; a runaway one is bounded by the file itself, but say so early.
    if (loop_.size() >= (1u << 20)) fail("a facet with more than 2^20 vertices");
    loop_.emplace_back(xyz[0], xyz[1], xyz[2]);
  }

  ByteReader reader_;
  LineReader lines_;
  State state_ = State::outside;
  std::vector<Vec3f> loop_;
  std::size_t fan_next_ = 0;  // next fan triangle of loop_ still to hand out ({0, i, i+1}); 0 when none
};

// One of the two parsers, chosen by looking at the file.
class StlParser {
 public:
  StlParser(const std::string& path, const std::function<void(const std::string&)>& warn) {
    ByteReader probe(path, 1 << 12);
    if (looks_ascii(probe)) {
      ascii_.emplace(path);
    } else {
      binary_.emplace(path, warn);
    }
  }
  bool read(std::vector<Corners>& out, std::size_t max) {
    return ascii_ ? ascii_->read(out, max) : binary_->read(out, max);
  }
  const ByteReader& reader() const { return ascii_ ? ascii_->reader() : binary_->reader(); }
  std::uint64_t triangles_hint() const { return binary_ ? binary_->triangles() : 0; }

 private:
  std::optional<AsciiStlParser> ascii_;
  std::optional<BinaryStlParser> binary_;
};

class StlStream final : public TriangleStream {
 public:
  StlStream(const std::string& path, const ReadOptions& options)
      : parser_(path, options.warn),
        capacity_(std::max<std::size_t>(options.batch_capacity, 1)),
        progress_(options.progress) {}

  bool next(TriangleBatch& batch) override {
    batch.clear();
    parser_.read(batch.corners, capacity_);
    const std::uint64_t done = bytes_read();
    if (progress_ && (done >= last_progress_ + kProgressStep || batch.corners.empty())) {
      last_progress_ = done;
      progress_("read", done, bytes_total());
    }
    return !batch.corners.empty();
  }

  const IndexedMesh& vertices() const override { return empty_; }

  Box3 bounds() override {
    if (!bounds_) {
      StlParser scan(path(), {});  // the stream's own parser has warned
      std::vector<Corners> corners;
      Box3 box;
      while (scan.read(corners, 1 << 16)) {
        for (const Corners& c : corners)
          for (const Vec3f& p : c) box.add(p);
        corners.clear();
      }
      bounds_ = box;
    }
    return *bounds_;
  }

  std::uint64_t triangles_hint() const override { return parser_.triangles_hint(); }
  std::uint64_t bytes_read() const override { return parser_.reader().offset(); }
  std::uint64_t bytes_total() const override { return parser_.reader().file_size(); }
  const std::string& path() const override { return parser_.reader().path(); }

 private:
  StlParser parser_;
  std::size_t capacity_;
  ProgressFn progress_;
  std::optional<Box3> bounds_;
  IndexedMesh empty_;
  std::uint64_t last_progress_ = 0;
};

Vec3f facet_normal(const Vec3f& a, const Vec3f& b, const Vec3f& c) {
  const Vec3d n = (b - a).cast<double>().cross((c - a).cast<double>());
  const double length = n.norm();
  return length > 0 ? Vec3f((n / length).cast<float>()) : Vec3f::Zero();
}

void write_binary(AtomicFile& file, const IndexedMesh& mesh, const WriteOptions& options) {
  // Deliberately not starting with "solid": that would make readers guess ASCII.
  char header[kHeaderBytes];
  std::memset(header, ' ', sizeof header);
  const std::string_view title = "binary STL written by ocsimp";
  std::memcpy(header, title.data(), title.size());
  file.write(header, sizeof header);
  const auto count = static_cast<std::uint32_t>(mesh.triangles.size());
  file.write(&count, 4);
  const std::size_t faces = mesh.triangles.size();
  for (std::size_t f = 0; f < faces; ++f) {
    const Triangle& t = mesh.triangles[f];
    const Vec3f& a = mesh.positions[t[0]];
    const Vec3f& b = mesh.positions[t[1]];
    const Vec3f& c = mesh.positions[t[2]];
    const Vec3f n = facet_normal(a, b, c);
    const float values[12] = {n.x(), n.y(), n.z(), a.x(), a.y(), a.z(),
                              b.x(), b.y(), b.z(), c.x(), c.y(), c.z()};
    char* p = file.reserve(kTriangleBytes);
    std::memcpy(p, values, 48);
    p[48] = p[49] = 0;
    file.advance(kTriangleBytes);
    if ((f & 0xFFFF) == 0xFFFF) report(options.progress, "write", f + 1, faces);
  }
}

void write_ascii(AtomicFile& file, const IndexedMesh& mesh, const WriteOptions& options) {
  file.write("solid ocsimp\n");
  const std::size_t faces = mesh.triangles.size();
  for (std::size_t f = 0; f < faces; ++f) {
    const Triangle& t = mesh.triangles[f];
    const Vec3f corners[3] = {mesh.positions[t[0]], mesh.positions[t[1]], mesh.positions[t[2]]};
    const Vec3f n = facet_normal(corners[0], corners[1], corners[2]);
    char* const start = file.reserve(512);
    char* p = start;
    auto text = [&p](std::string_view s) {
      std::memcpy(p, s.data(), s.size());
      p += s.size();
    };
    auto triple = [&](const Vec3f& v) {
      for (int k = 0; k < 3; ++k) {
        *p++ = ' ';
        p = print_float(p, v[k]);
      }
      *p++ = '\n';
    };
    text("  facet normal");
    triple(n);
    text("    outer loop\n");
    for (const Vec3f& c : corners) {
      text("      vertex");
      triple(c);
    }
    text("    endloop\n  endfacet\n");
    file.advance(static_cast<std::size_t>(p - start));
    if ((f & 0xFFFF) == 0xFFFF) report(options.progress, "write", f + 1, faces);
  }
  file.write("endsolid ocsimp\n");
}

}  // namespace

std::unique_ptr<TriangleStream> open_stl_stream(const std::string& path, const ReadOptions& options) {
  return std::make_unique<StlStream>(path, options);
}

void write_stl(const std::string& path, const IndexedMesh& mesh, const WriteOptions& options) {
  check_writable(path, mesh);
  if (!options.ascii && mesh.triangles.size() > std::numeric_limits<std::uint32_t>::max())
    throw Error(path, {}, "cannot write: binary STL holds at most 2^32-1 triangles");
  AtomicFile file(path);
  if (options.ascii) {
    write_ascii(file, mesh, options);
  } else {
    write_binary(file, mesh, options);
  }
  // Before the commit: a callback that throws (a cancel) must leave no file behind.
  report(options.progress, "write", mesh.triangles.size(), mesh.triangles.size());
  file.commit();
}

}  // namespace ocsimp::detail
