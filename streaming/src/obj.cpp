// Wavefront OBJ: text, indexed, no header, and no promise that a vertex comes before the faces using it.
//
// Reading takes two passes over the file (three when faces reference texture coordinates or normals):
//   1. load every v / vt / vn record (memory grows with the records actually present, never with a count);
//   2. (only with attributes) walk the faces to give each position the vt / vn of the first face corner that
//      references it - OBJ indexes attributes separately, our meshes keep one of each per position, so
//      positions shared across a uv seam keep the first corner's uv;
//   3. stream the faces, triangulating polygons (see polygon.h).
// Passes 2 and 3 start at the first face statement, since everything before it was loaded already.
// Negative indices count back from the records read so far at that line, as the format specifies.
// Accepted and ignored: comments (whole lines, or from a '#' after a statement), o g s usemtl mtllib l p vp
// and any unknown statement, unless the file has no vertex at all: text that only starts like an OBJ (a
// README's '#' heading) is refused at its first line that is no OBJ statement. A '\' at the end of a line
// continues the statement on the next one.
#include <algorithm>
#include <array>
#include <charconv>
#include <cstring>
#include <functional>
#include <limits>
#include <map>
#include <string>
#include <string_view>
#include <unordered_map>
#include <utility>
#include <vector>

#include "byte_reader.h"
#include "formats.h"
#include "ocsimp/core/error.h"
#include "ocsimp/streaming/atomic_file.h"
#include "origin_sample.h"
#include "polygon.h"
#include "text_io.h"

namespace ocsimp::detail {
namespace {

constexpr Index kNone = std::numeric_limits<Index>::max();
// A statement continued over many lines is still held whole; beyond this it is an error, not an allocation.
constexpr std::size_t kMaxStatementBytes = 64u << 20;
constexpr std::uint64_t kProgressStep = 8u << 20;

enum class Keyword { blank, v, vt, vn, f, other };

struct RecordCounts {
  std::uint64_t v = 0, vt = 0, vn = 0;
};

struct Corner {
  Index v, vt, vn;  // 0-based; vt / vn are kNone when the corner has none
};

// The statement keyword of `line`; `rest` is set just past it.
Keyword classify(std::string_view line, const char*& rest) {
  const char* end = line.data() + line.size();
  const char* p = skip_blanks(line.data(), end);
  const char* e = token_end(p, end);
  rest = e;
  const std::size_t n = static_cast<std::size_t>(e - p);
  if (n == 0) return Keyword::blank;
  if (p[0] == 'v') {
    if (n == 1) return Keyword::v;
    if (n == 2 && p[1] == 't') return Keyword::vt;
    if (n == 2 && p[1] == 'n') return Keyword::vn;
  } else if (p[0] == 'f' && n == 1) {
    return Keyword::f;
  }
  return Keyword::other;
}

constexpr Color kWhite{255, 255, 255, 255};  // a vertex without colors in a file where others have them

std::uint8_t color_channel(float value) {
  return static_cast<std::uint8_t>(std::clamp(value, 0.0f, 1.0f) * 255.0f + 0.5f);
}

class ObjStream final : public TriangleStream {
 public:
  ObjStream(const std::string& path, const ReadOptions& options)
      : reader_(path),
        lines_(reader_),
        capacity_(std::max<std::size_t>(options.batch_capacity, 1)),
        progress_(options.progress),
        warn_(options.warn),
        vertex_sink_(options.vertex_sink),
        split_(options.split_corner_attributes && !options.vertex_sink) {
    try {
      load_records();
    } catch (const Error&) {
      // A vertex held for the origin's sample may be bad too, and it comes first in the file: that is the
      // error to report (settle_origin throws it), taken against the origin of the vertices read so far.
      if (!origin_sample_.settled) settle_origin();
      throw;
    }
    passes_ = needs_attribute_pass_ ? 3 : 2;
    if (needs_attribute_pass_) {
      restart_pass();
      assign_attributes();
    }
    restart_pass();
  }

  bool next(TriangleBatch& batch) override {
    batch.clear();
    while (pending_next_ < pending_.size() && batch.triangles.size() < capacity_)
      batch.triangles.push_back(pending_[pending_next_++]);
    std::string_view line;
    while (batch.triangles.size() < capacity_ && next_statement(line)) {
      const char* rest;
      switch (classify(line, rest)) {
        case Keyword::v:
          ++seen_.v;
          break;
        case Keyword::vt:
          ++seen_.vt;
          break;
        case Keyword::vn:
          ++seen_.vn;
          break;
        case Keyword::f:
          parse_face(rest, line.data() + line.size());
          if (!copies_.empty()) {
            for (Corner& c : corners_) c.v = corner_vertex(c);
          }
          emit_triangles(batch);
          break;
        default:
          break;
      }
      report_progress();
    }
    if (batch.size() > 0) return true;
    if (warn_ && !unread_note_.empty()) warn_(std::exchange(unread_note_, {}));
    if (warn_ && concave_fans_ > 0) warn_(concave_fans_note(std::exchange(concave_fans_, 0)));
    return false;
  }

  const IndexedMesh& vertices() const override { return vertices_; }
  Box3 bounds() override { return bounds_; }
  // OBJ declares nothing; this is the number of face statements counted while loading the vertices.
  std::uint64_t triangles_hint() const override { return face_statements_; }
  std::uint64_t bytes_read() const override { return reader_.offset(); }
  std::uint64_t bytes_total() const override { return reader_.file_size(); }
  const std::string& path() const override { return reader_.path(); }
  std::string attributes_left_out() const override {
    if (!vertex_sink_) return {};
    return attribute_list(total_.vn > 0, sink_dropped_colors_, total_.vt > 0);
  }

 private:
  // Whether the statement's keyword is one the OBJ format defines (free-form geometry, grouping, display and
  // rendering attributes), all ignored here but v, vt, vn and f.
  static bool known_statement(std::string_view line) {
    const char* end = line.data() + line.size();
    const char* p = skip_blanks(line.data(), end);
    const std::string_view keyword(p, static_cast<std::size_t>(token_end(p, end) - p));
    if (keyword.starts_with('#')) return true;  // a comment
    for (std::string_view k :
         {"o",      "g",      "s",          "mg",        "usemtl", "mtllib", "l",        "p",        "vp",
          "cstype", "deg",    "bmat",       "step",      "curv",   "curv2",  "surf",     "parm",     "trim",
          "hole",   "scrv",   "sp",         "end",       "con",    "bevel",  "c_interp", "d_interp", "lod",
          "usemap", "maplib", "shadow_obj", "trace_obj", "ctech",  "stech",  "call",     "csh"}) {
      if (keyword == k) return true;
    }
    return false;
  }

  [[noreturn]] void fail(const std::string& reason) const {
    throw Error(reader_.path(), FilePosition::line(statement_line_), reason);
  }

  // The next statement with any '\' continuations joined; blank and comment lines included. A comment may
  // also follow a statement ("v 1 2 3 # corner", as most readers allow): the parsers below stop at its '#'.
  bool next_statement(std::string_view& line) {
    statement_offset_ = reader_.offset();
    if (!lines_.next(line)) return false;
    statement_line_ = lines_.line_number();
    // A '\' that ends a comment (a Windows path) continues nothing.
    auto continued = [](std::string_view text) {
      return !text.empty() && text.back() == '\\' && text.find('#') == std::string_view::npos;
    };
    if (!continued(line)) return true;
    joined_.assign(line.data(), line.size() - 1);
    std::string_view more;
    while (lines_.next(more)) {
      joined_.push_back(' ');
      const bool continues = continued(more);
      joined_.append(more.data(), continues ? more.size() - 1 : more.size());
      if (joined_.size() > kMaxStatementBytes)
        fail("statement continued over more than " + std::to_string(kMaxStatementBytes) + " bytes");
      if (!continues) break;
    }
    line = joined_;
    return true;
  }

  // Later passes only need the faces: they start at the first face statement, with the record counts the
  // load pass saw before it (most files list every vertex first, so this skips about half the file).
  void restart_pass() {
    ++pass_;
    lines_.restart_at(first_face_.offset, first_face_.line);
    seen_ = first_face_.seen;
    statement_line_ = 0;
  }

  void report_progress() {
    if (!progress_) return;
    const std::uint64_t done = (pass_ - 1) * reader_.file_size() + reader_.offset();
    if (done < last_progress_ + kProgressStep) return;
    last_progress_ = done;
    progress_("read", done, passes_ * reader_.file_size());
  }

  // Pass 1: v, vt and vn records.
  void load_records() {
    std::string_view line;
    while (next_statement(line)) {
      const char* rest;
      const char* end = line.data() + line.size();
      switch (classify(line, rest)) {
        case Keyword::v:
          parse_vertex(rest, end);
          ++seen_.v;
          break;
        case Keyword::vt:
          parse_uv(rest, end);
          ++seen_.vt;
          break;
        case Keyword::vn:
          parse_normal(rest, end);
          ++seen_.vn;
          break;
        case Keyword::f:
          if (face_statements_ == 0) first_face_ = {statement_offset_, statement_line_, seen_};
          ++face_statements_;
          if (!faces_have_slashes_ && std::memchr(rest, '/', static_cast<std::size_t>(end - rest)))
            faces_have_slashes_ = true;
          break;
        case Keyword::other:
          note_unread(line);
          // Only before the first vertex, where the error can still apply: files of many g / usemtl lines
          // pay nothing after it.
          if (seen_.v == 0 && first_unknown_line_ == 0 && !known_statement(line)) {
            first_unknown_line_ = statement_line_;
            first_unknown_ = quote_token(skip_blanks(line.data(), end), end);
          }
          break;
        default:
          break;
      }
      report_progress();
    }
    if (seen_.v == 0 && first_unknown_line_ > 0) {
      statement_line_ = first_unknown_line_;
      fail(first_unknown_ + " is no OBJ statement, and the file has no vertex: not an OBJ file");
    }
    if (face_statements_ == 0) first_face_ = {reader_.file_size(), lines_.line_number() + 1, seen_};
    needs_attribute_pass_ = faces_have_slashes_ && (!uv_records_.empty() || !normal_records_.empty());
    if (!origin_sample_.settled) settle_origin();  // fewer vertices than the sample
    flush_sink();
    total_ = seen_;
    if (warn_ && clamped_colors_ > 0) warn_(clamped_colors_note(clamped_colors_));
    unread_note_ = unread_note({material_libraries_, materials_, other_geometry_});
  }

  // Materials and geometry other than faces, for unread_note: the output has no place for them.
  void note_unread(std::string_view line) {
    const char* end = line.data() + line.size();
    const char* p = skip_blanks(line.data(), end);
    const char* keyword_end = token_end(p, end);
    const std::string_view keyword(p, static_cast<std::size_t>(keyword_end - p));
    // The argument: the rest of the statement up to a comment, without the blanks around it (a material or
    // library name may hold blanks).
    auto argument = [&] {
      const char* first = skip_blanks(keyword_end, end);
      const char* last = std::find(first, end, '#');
      while (last > first && (last[-1] == ' ' || last[-1] == '\t' || last[-1] == '\r')) --last;
      return std::string_view(first, static_cast<std::size_t>(last - first));
    };
    if (keyword == "mtllib") {
      material_libraries_.add(argument());
    } else if (keyword == "usemtl") {
      materials_.add(argument());
    } else if (keyword == "l") {
      other_geometry_.add("polylines (l)");
    } else if (keyword == "p") {
      other_geometry_.add("points (p)");
    } else if (keyword == "curv" || keyword == "curv2" || keyword == "surf") {
      other_geometry_.add("free-form curves and surfaces");
    }
  }

  // Up to `max` numbers into `values` (float or double); returns how many there were.
  template <class Number>
  int parse_numbers(const char* p, const char* end, Number* values, int max) {
    int count = 0;
    while (true) {
      Number value;
      const NumberStatus status = parse_number(p, end, value, /*comment_ends=*/true);
      if (status == NumberStatus::missing) return count;
      if (status != NumberStatus::ok) fail(describe(status, p, end));
      if (count == max) fail("too many numbers: " + quote_token(p, end) + " after " + std::to_string(max));
      values[count++] = value;
    }
  }

  void parse_vertex(const char* p, const char* end) {
    float values[7];
    const int count = vertices_.origin != Vec3d::Zero() ? parse_far_vertex(p, end, values)
                                                        : parse_numbers(p, end, values, 7);
    if (count != 3 && count != 4 && count != 6 && count != 7)
      fail("a vertex needs x y z, optionally w, optionally r g b (found " + counted(count, "number") + ")");
    if (seen_.v >= kNone) fail("more than 2^32-2 vertices");
    const Vec3f position(values[0], values[1], values[2]);
    if (!origin_sample_.settled) {
      // Also held in double until the origin is chosen from them (see settle_origin).
      double precise[7];
      parse_numbers(p, end, precise, 7);
      origin_sample_.held.push_back(
          {Vec3d(precise[0], precise[1], precise[2]), FilePosition::line(statement_line_)});
    } else {
      bounds_.add(position);
    }
    const bool has_color = count >= 6;
    const float* rgb = values + (count - 3);
    if (has_color &&
        !(rgb[0] >= 0 && rgb[0] <= 1 && rgb[1] >= 0 && rgb[1] <= 1 && rgb[2] >= 0 && rgb[2] <= 1))
      ++clamped_colors_;
    const Color color =
        has_color ? Color{color_channel(rgb[0]), color_channel(rgb[1]), color_channel(rgb[2]), 255} : kWhite;
    if (vertex_sink_) {
      sink_buffer_.push_back(position);
      // Colors go with the positions when a vertex of the first chunk has them (the spool's records are
      // fixed by it); vertices without them are white, as in core.
      const bool carried =
          sink_colors_ == SinkColors::carried ||
          (sink_colors_ == SinkColors::undecided && (has_color || !sink_colors_buffer_.empty()));
      if (carried) {
        if (sink_colors_buffer_.empty()) sink_colors_buffer_.assign(sink_buffer_.size() - 1, kWhite);
        sink_colors_buffer_.push_back(color);
      } else if (has_color) {
        sink_dropped_colors_ = true;
      }
    } else {
      vertices_.positions.push_back(position);
      if (has_color && vertices_.colors.empty())
        vertices_.colors.assign(vertices_.positions.size() - 1, kWhite);
      if (has_color || !vertices_.colors.empty()) vertices_.colors.push_back(color);
    }
    if (!origin_sample_.settled && origin_sample_.full()) settle_origin();
    if (vertex_sink_ && sink_buffer_.size() == kSinkChunk) flush_sink();
  }

  // Chooses the origin from the vertices held so far (OriginSample::settle): they are still at the front of
  // the positions (nothing reaches the sink before this). Once it is away from zero, every later vertex is
  // read in double (parse_far_vertex).
  void settle_origin() {
    vertices_.origin =
        origin_sample_.settle(reader_.path(), 1, vertex_sink_ ? sink_buffer_ : vertices_.positions, bounds_);
  }

  // A vertex once the origin is away from zero: x y z read as doubles, then taken relative to it before they
  // are narrowed to float. Returns the count of numbers.
  [[gnu::noinline]] int parse_far_vertex(const char* p, const char* end, float* values) {
    double precise[7];
    const int count = parse_numbers(p, end, precise, 7);
    for (int k = 0; k < count; ++k) {
      // Beyond float's range a number is refused with the message a float parse gives.
      constexpr double kLargest = std::numeric_limits<float>::max();
      if (!(std::abs(precise[k]) <= kLargest)) parse_numbers(p, end, values, 7);
      values[k] = static_cast<float>(std::clamp(precise[k], -kLargest, kLargest));  // text that rounds to it
    }
    if (count >= 3) {
      const Vec3f position = float_offset(Vec3d(precise[0], precise[1], precise[2]), vertices_.origin,
                                          reader_.path(), FilePosition::line(statement_line_), seen_.v + 1);
      for (int k = 0; k < 3; ++k) values[k] = position[k];
    }
    return count;
  }

  void parse_uv(const char* p, const char* end) {
    float values[3];
    const int count = parse_numbers(p, end, values, 3);
    if (count == 0) fail("a texture coordinate needs u [v [w]]");
    if (vertex_sink_) return;  // out of core: per-corner records are left out
    uv_records_.emplace_back(values[0], count > 1 ? values[1] : 0.0f);
  }

  void parse_normal(const char* p, const char* end) {
    float values[3];
    if (parse_numbers(p, end, values, 3) != 3) fail("a normal needs x y z");
    if (vertex_sink_) return;
    normal_records_.emplace_back(values[0], values[1], values[2]);
  }

  // One index of a face corner: 1-based, or negative to count back from the `seen` records so far.
  Index parse_index(const char*& p, const char* end, std::uint64_t seen, std::uint64_t total,
                    const char* what, const char* corner) {
    bool negative = false;
    if (p < end && (*p == '-' || *p == '+')) negative = *p++ == '-';
    const char* digits = p;
    std::uint64_t value = 0;
    for (; p < end && static_cast<unsigned char>(*p - '0') < 10; ++p)
      value = value * 10 + static_cast<unsigned>(*p - '0');
    if (p == digits) fail("malformed face corner " + quote_token(corner, end));
    if (p - digits > 12) value = std::uint64_t(1) << 40;  // past any count; the digits above may have wrapped
    if (value == 0)
      fail(std::string(what) + " index 0 in " + quote_token(corner, end) + " (OBJ counts from 1)");
    // Errors quote the index as written: the value is clamped past 12 digits.
    const std::string_view written(digits, static_cast<std::size_t>(p - digits));
    if (negative) {
      if (value > seen)
        fail("relative " + std::string(what) + " index -" + std::string(written) +
             " reaches before the first " + what + " (" + std::to_string(seen) + " so far)");
      return static_cast<Index>(seen - value);
    }
    if (value > total)
      fail(std::string(what) + " index " + std::string(written) + " out of range (the file has " +
           std::to_string(total) + ")");
    return static_cast<Index>(value - 1);
  }

  // Corners of the face statement into corners_: "v", "v/vt", "v//vn" or "v/vt/vn" each.
  void parse_face(const char* p, const char* end) {
    corners_.clear();
    while ((p = skip_blanks(p, end)) < end && *p != '#') {
      const char* corner = p;
      Corner c{parse_index(p, end, seen_.v, total_.v, "vertex", corner), kNone, kNone};
      if (p < end && *p == '/') {
        ++p;
        if (p < end && *p != '/')
          c.vt = parse_index(p, end, seen_.vt, total_.vt, "texture coordinate", corner);
        if (p < end && *p == '/') {
          ++p;
          c.vn = parse_index(p, end, seen_.vn, total_.vn, "normal", corner);
        }
      }
      if (p < end && !is_blank(*p) && *p != '#') fail("malformed face corner " + quote_token(corner, end));
      corners_.push_back(c);
    }
    if (corners_.size() < 3)
      fail("a face needs at least 3 corners (found " + std::to_string(corners_.size()) + ")");
  }

  // The face's triangles: a polygon's are cut in its plane (see polygon.h), but for a fan where the
  // positions went to a vertex sink instead of memory (the out-of-core path).
  void emit_triangles(TriangleBatch& batch) {
    pending_.clear();
    pending_next_ = 0;
    auto emit = [&](const Triangle& t) {
      if (batch.triangles.size() < capacity_) {
        batch.triangles.push_back(t);
      } else {
        pending_.push_back(t);
      }
    };
    if (corners_.size() == 3) return emit(Triangle{corners_[0].v, corners_[1].v, corners_[2].v});
    polygon_.clear();
    for (const Corner& c : corners_) polygon_.push_back(c.v);
    polygon_.resize(drop_repeated_corners(polygon_.data(), polygon_.size(),
                                          [&](Index a, Index b) { return same_point(a, b); }));
    if (!positions_known()) return fan_triangles(polygon_.data(), polygon_.size(), emit);
    concave_fans_ += polygon_triangles(
        polygon_.data(), polygon_.size(), [&](std::size_t i) { return position(polygon_[i]); },
        polygon_scratch_, emit);
  }

  void flush_sink() {
    if (sink_buffer_.empty()) return;
    if (sink_colors_ == SinkColors::undecided)
      sink_colors_ = sink_colors_buffer_.empty() ? SinkColors::none : SinkColors::carried;
    VertexChunk chunk;
    chunk.positions = sink_buffer_;
    chunk.colors = sink_colors_buffer_;
    vertex_sink_(chunk);
    sink_buffer_.clear();
    sink_colors_buffer_.clear();
  }

  // With split_: the vertex corner c stands for, the file's own or a copy of it with the corner's texture
  // coordinate and normal. The copies are made in pass 2 (while the first corners still assign the file's
  // vertices their attributes) and looked up in pass 3, which meets the corners in the same order and so
  // makes the same comparisons.
  Index corner_vertex(const Corner& c) {
    const Index v = c.v;
    const bool uv_differs = c.vt != kNone && !vertices_.uvs.empty() && vertices_.uvs[v] != uv_records_[c.vt];
    const bool normal_differs =
        c.vn != kNone && !vertices_.normals.empty() && vertices_.normals[v] != normal_records_[c.vn];
    if (!uv_differs && !normal_differs) return v;
    const Vec2f uv = uv_differs ? uv_records_[c.vt] : Vec2f::Zero();
    const Vec3f normal = normal_differs ? normal_records_[c.vn] : Vec3f::Zero();
    CopyKey key{v, uv_differs, normal_differs, {uv.x(), uv.y()}, {normal.x(), normal.y(), normal.z()}};
    if (vertices_.positions.size() >= kNone)
      fail("too many vertices once texture seams and hard edges are split");
    const auto [at, added] = copies_.emplace(key, static_cast<Index>(vertices_.positions.size()));
    if (added) {
      vertices_.positions.push_back(vertices_.positions[v]);
      if (!vertices_.colors.empty()) vertices_.colors.push_back(vertices_.colors[v]);
      // An attribute the corner agrees on is the file vertex's, which a later corner may still assign: the
      // copies take it after pass 2 (see copy_agreed_attributes).
      if (!vertices_.uvs.empty()) vertices_.uvs.push_back(uv);
      if (!vertices_.normals.empty()) vertices_.normals.push_back(normal);
    }
    return at->second;
  }

  void copy_agreed_attributes() {
    for (const auto& [key, copy] : copies_) {
      if (!key.uv_differs && !vertices_.uvs.empty()) vertices_.uvs[copy] = vertices_.uvs[key.v];
      if (!key.normal_differs && !vertices_.normals.empty())
        vertices_.normals[copy] = vertices_.normals[key.v];
    }
  }

  // Pass 2 (with attributes only): the first corner that references a position gives it its vt and vn;
  // those whose later corners disagree are counted for ReadOptions::warn, or with split_ get copies.
  void assign_attributes() {
    const std::size_t n = vertices_.positions.size();
    std::vector<std::uint8_t> has_uv(uv_records_.empty() ? 0 : n, 0),
        has_normal(normal_records_.empty() ? 0 : n, 0);
    std::uint64_t uv_seams = 0, hard_edges = 0;
    std::string_view line;
    while (next_statement(line)) {
      const char* rest;
      switch (classify(line, rest)) {
        case Keyword::v:
          ++seen_.v;
          break;
        case Keyword::vt:
          ++seen_.vt;
          break;
        case Keyword::vn:
          ++seen_.vn;
          break;
        case Keyword::f:
          parse_face(rest, line.data() + line.size());
          for (const Corner& c : corners_) {
            if (c.vt != kNone) {
              if (vertices_.uvs.empty()) vertices_.uvs.assign(n, Vec2f::Zero());
              take_first_corner(has_uv, vertices_.uvs, c.v, uv_records_[c.vt], uv_seams);
            } else if (!has_uv.empty() && has_uv[c.v] == 0) {
              has_uv[c.v] = kCornerWithout;
            }
            if (c.vn != kNone) {
              if (vertices_.normals.empty()) vertices_.normals.assign(n, Vec3f::Zero());
              take_first_corner(has_normal, vertices_.normals, c.v, normal_records_[c.vn], hard_edges);
            } else if (!has_normal.empty() && has_normal[c.v] == 0) {
              has_normal[c.v] = kCornerWithout;
            }
            if (split_) corner_vertex(c);
          }
          break;
        default:
          break;
      }
      report_progress();
    }
    if (copies_.empty()) {
      uv_records_ = {};
      normal_records_ = {};
    } else {
      copy_agreed_attributes();  // pass 3 still compares corners with the records
    }
    if (warn_ && !split_ && uv_seams + hard_edges > 0) warn_(merged_corners_note(uv_seams, hard_edges));
    // A file where only some faces give vt or vn: the vertices only those without reference get made-up
    // values, which simplification then blends into the real ones.
    auto without = [](const std::vector<std::uint8_t>& state, bool kept) {
      return kept ? static_cast<std::uint64_t>(std::count(state.begin(), state.end(), kCornerWithout)) : 0;
    };
    const std::uint64_t no_uv = without(has_uv, !vertices_.uvs.empty()),
                        no_normal = without(has_normal, !vertices_.normals.empty());
    if (warn_ && no_uv + no_normal > 0) {
      auto part = [](std::uint64_t k, const char* what, const char* given) {
        return std::to_string(k) + (k == 1 ? " vertex is" : " vertices are") +
               " used only by faces without " + what + " and " + (k == 1 ? "gets " : "get ") + given;
      };
      std::string note;
      if (no_uv > 0) note = part(no_uv, "texture coordinates (vt)", "(0, 0)");
      if (no_normal > 0)
        note += (note.empty() ? "" : "; ") + part(no_normal, "normals (vn)", "a zero normal");
      warn_(note);
    }
  }

  ByteReader reader_;
  LineReader lines_;
  std::size_t capacity_;
  ProgressFn progress_;
  std::function<void(const std::string&)> warn_;
  // What the file holds that no output keeps (unread_note), said once every face is read: a file that then
  // fails got the warning and its error both.
  std::string unread_note_;
  std::uint64_t clamped_colors_ = 0;  // vertices with a color channel outside [0, 1]
  std::uint64_t concave_fans_ = 0;    // polygons polygon_triangles fanned though concave
  // Out of core (ReadOptions::vertex_sink): positions and colors go there a chunk at a time; no vertex array
  // is kept.
  std::function<void(const VertexChunk&)> vertex_sink_;
  // Out of core, whether vertex colors go to the sink: decided by its first chunk.
  enum class SinkColors { undecided, carried, none };
  SinkColors sink_colors_ = SinkColors::undecided;
  std::vector<Color> sink_colors_buffer_;
  bool sink_dropped_colors_ = false;  // a vertex after the first chunk had colors, which the sink cannot take
  OriginSample origin_sample_{{}, /*settled=*/false};  // OBJ text is more precise than floats
  std::vector<Vec3f> sink_buffer_;
  static constexpr std::size_t kSinkChunk = 1 << 16;
  // The origin's sample is complete before the first chunk goes (settle_origin rewrites it in place).
  static_assert(kSinkChunk > kOriginSample);

  IndexedMesh vertices_;
  Box3 bounds_;
  std::vector<Vec2f> uv_records_;
  std::vector<Vec3f> normal_records_;
  RecordCounts total_;
  RecordCounts seen_;  // records passed so far in the current pass, for relative indices
  std::uint64_t face_statements_ = 0;
  std::uint64_t first_unknown_line_ = 0;  // of the first statement the format does not define (0: none)
  std::string first_unknown_;             // its keyword, quoted
  UnreadData material_libraries_{"material library", "material libraries", {}};
  UnreadData materials_{"material", "materials", {}};
  UnreadData other_geometry_{"geometry other than faces:", "geometry other than faces:", {}};
  bool faces_have_slashes_ = false;
  bool needs_attribute_pass_ = false;

  struct Resume {
    std::uint64_t offset = 0, line = 1;
    RecordCounts seen;
  };
  Resume first_face_;

  std::uint64_t statement_line_ = 0;
  std::uint64_t statement_offset_ = 0;
  std::string joined_;
  std::vector<Corner> corners_;
  // split_: the copies of file vertices, by vertex and the attributes they differ in (values, not record
  // indices: two vt records of one value are one side of a seam).
  struct CopyKey {
    Index v;
    bool uv_differs, normal_differs;
    std::array<float, 2> uv;
    std::array<float, 3> normal;
    auto operator<=>(const CopyKey&) const = default;
  };
  bool split_ = false;
  std::map<CopyKey, Index> copies_;
  std::vector<Triangle> pending_;  // the rest of a polygon's triangles that did not fit the last batch
  std::vector<Index> polygon_;     // the face's vertices
  PolygonScratch polygon_scratch_;
  std::size_t pending_next_ = 0;

  std::uint64_t pass_ = 1, passes_ = 2;
  std::uint64_t last_progress_ = 0;
};

char* print_index(char* out, Index i) {
  return std::to_chars(out, out + 12, std::uint64_t(i) + 1).ptr;
}

// The `v` line of each vertex. A texture seam or hard edge holds one vertex per side at one position (a
// reader asked to split corners, or the decimator, writes such copies); OBJ indexes positions apart from uvs
// and normals, so the sides share one `v` line and each corner names its own `vt` and `vn`. The file is then
// closed where the surface is, as the input was, rather than cut open along every seam. Copies whose uv and
// normal are equal too are no seam but a crack the mesh has, and keep lines of their own. Empty without uvs
// or normals, where every vertex keeps its own line.
std::vector<Index> position_lines(const IndexedMesh& mesh, Index* lines) {
  const std::size_t n = mesh.positions.size();
  *lines = static_cast<Index>(n);
  if (!mesh.has_uvs() && !mesh.has_normals()) return {};
  std::vector<Index> line(n);
  struct Key {
    PositionKey position;
    Color color;
    bool operator==(const Key&) const = default;
  };
  struct KeyHash {
    std::size_t operator()(const Key& k) const {
      std::uint32_t c;
      std::memcpy(&c, k.color.data(), sizeof c);
      return static_cast<std::size_t>(k.position.hash() ^ (c * 0x9E3779B97F4A7C15ull));
    }
  };
  // Per key, the first vertex of the group its next copy would join; groups are chained through `next`.
  std::unordered_map<Key, Index, KeyHash> group_of;
  std::vector<Index> next(n, kNone);
  auto same_attributes = [&](std::size_t a, std::size_t b) {
    const bool uv = !mesh.has_uvs() || mesh.uvs[a] == mesh.uvs[b];
    const bool normal = !mesh.has_normals() || mesh.normals[a] == mesh.normals[b];
    return uv && normal;
  };
  Index count = 0;
  for (std::size_t v = 0; v < n; ++v) {
    const Key key{PositionKey(mesh.positions[v]), mesh.has_colors() ? mesh.colors[v] : Color{}};
    auto [it, inserted] = group_of.try_emplace(key, static_cast<Index>(v));
    if (!inserted) {
      Index last = it->second;
      bool crack = same_attributes(last, v);
      while (!crack && next[last] != kNone) {
        last = next[last];
        crack = same_attributes(last, v);
      }
      if (!crack) {
        next[last] = static_cast<Index>(v);
        line[v] = line[it->second];
        continue;
      }
      it->second = static_cast<Index>(v);  // a new group, which later copies join
    }
    line[v] = count++;
  }
  *lines = count;
  return line;
}

}  // namespace

std::unique_ptr<TriangleStream> open_obj_stream(const std::string& path, const ReadOptions& options) {
  return std::make_unique<ObjStream>(path, options);
}

void write_obj(const std::string& path, const IndexedMesh& mesh, const WriteOptions& options) {
  check_writable(path, mesh);
  Index lines = 0;
  const std::vector<Index> line = position_lines(mesh, &lines);
  AtomicFile file(path);
  file.write("# ocsimp: " + std::to_string(lines) + " vertices, " + std::to_string(mesh.triangles.size()) +
             " triangles\n");
  const bool colors = mesh.has_colors(), uvs = mesh.has_uvs(), normals = mesh.has_normals();
  const bool shifted = mesh.origin != Vec3d::Zero();
  for (std::size_t i = 0, written = 0; i < mesh.positions.size(); ++i) {
    if (!line.empty() && line[i] != written) continue;  // a seam copy: its group's line is out
    ++written;
    char* const start = file.reserve(128);  // "v", 3 doubles and 3 floats with their separators, "\n"
    char* p = start;
    *p++ = 'v';
    for (int k = 0; k < 3; ++k) {
      *p++ = ' ';
      p = shifted ? print_double(p, mesh.origin[k] + double(mesh.positions[i][k]))
                  : print_float(p, mesh.positions[i][k]);
    }
    if (colors) {
      // OBJ's color extension has no alpha.
      for (int k = 0; k < 3; ++k) {
        *p++ = ' ';
        p = print_float(p, float(mesh.colors[i][k]) / 255.0f);
      }
    }
    *p++ = '\n';
    file.advance(static_cast<std::size_t>(p - start));
  }
  for (std::size_t i = 0; uvs && i < mesh.uvs.size(); ++i) {
    char* const start = file.reserve(64);
    char* p = start;
    *p++ = 'v';
    *p++ = 't';
    for (int k = 0; k < 2; ++k) {
      *p++ = ' ';
      p = print_float(p, mesh.uvs[i][k]);
    }
    *p++ = '\n';
    file.advance(static_cast<std::size_t>(p - start));
  }
  for (std::size_t i = 0; normals && i < mesh.normals.size(); ++i) {
    char* const start = file.reserve(64);
    char* p = start;
    *p++ = 'v';
    *p++ = 'n';
    for (int k = 0; k < 3; ++k) {
      *p++ = ' ';
      p = print_float(p, mesh.normals[i][k]);
    }
    *p++ = '\n';
    file.advance(static_cast<std::size_t>(p - start));
  }
  const std::size_t faces = mesh.triangles.size();
  for (std::size_t f = 0; f < faces; ++f) {
    char* const start = file.reserve(128);
    char* p = start;
    *p++ = 'f';
    for (Index v : mesh.triangles[f]) {
      *p++ = ' ';
      p = print_index(p, line.empty() ? v : line[v]);
      if (uvs || normals) {
        *p++ = '/';
        if (uvs) p = print_index(p, v);
        if (normals) {
          *p++ = '/';
          p = print_index(p, v);
        }
      }
    }
    *p++ = '\n';
    file.advance(static_cast<std::size_t>(p - start));
    if ((f & 0xFFFF) == 0xFFFF) report(options.progress, "write", f + 1, faces);
  }
  // Before the commit: a callback that throws (a cancel) must leave no file behind.
  report(options.progress, "write", faces, faces);
  file.commit();
}

}  // namespace ocsimp::detail
