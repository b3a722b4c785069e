// Helpers shared by the text formats (OBJ, ASCII STL): whole lines over a ByteReader, whitespace-separated
// tokens, strict number parsing, shortest round-trip float printing, and the checks every writer makes.
#pragma once

#include <fast_float/fast_float.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <string>
#include <string_view>
#include <type_traits>

#include "byte_reader.h"
#include "ocsimp/core/error.h"
#include "ocsimp/core/mesh.h"

namespace ocsimp::detail {

// Splits the input into lines ("\n" or "\r\n", or "\r" alone as old Mac tools wrote, told from the first
// buffer; a final line without terminator counts). A line must fit in the reader's buffer: longer ones are an
// error rather than a reason to grow memory.
class LineReader {
 public:
  explicit LineReader(ByteReader& reader) : reader_(reader) {}

  // The next line without its terminator; false at the end of the input. The view stays valid until the
  // next call.
  bool next(std::string_view& line) {
    std::size_t available = reader_.available();
    if (available == 0 && (available = reader_.fill(1)) == 0) return false;
    if (terminator_ == 0) available = choose_terminator();
    const char* data = reader_.data();
    const char* newline = static_cast<const char*>(std::memchr(data, terminator_, available));
    if (newline == nullptr) {
      available = reader_.fill(reader_.capacity());
      data = reader_.data();
      newline = static_cast<const char*>(std::memchr(data, terminator_, available));
      if (newline == nullptr && available == reader_.capacity()) {
        throw Error(reader_.path(), FilePosition::line(line_ + 1),
                    "line longer than " + std::to_string(reader_.capacity()) + " bytes");
      }
    }
    std::size_t length = newline ? static_cast<std::size_t>(newline - data) : available;
    reader_.consume(newline ? length + 1 : length);
    ++line_;
    if (terminator_ == '\n' && length > 0 && data[length - 1] == '\r') --length;
    line = std::string_view(data, length);
    // A UTF-8 byte order mark before the first line (as some Windows editors write) is not part of it.
    if (line_ == 1 && line.starts_with("\xEF\xBB\xBF")) line.remove_prefix(3);
    return true;
  }

  // 1-based number of the line last returned by next().
  std::uint64_t line_number() const { return line_; }

  // Continues from byte `offset`, the start of line `line` (1-based), as a previous pass recorded them.
  void restart_at(std::uint64_t offset, std::uint64_t line) {
    reader_.seek(offset);
    line_ = line - 1;
  }

 private:
  // Sets terminator_: "\r" when the first buffer holds a "\r" and no "\n" at all, else "\n". Without this, a
  // whole file of CR-only lines read as one line and failed at its first word with an error that did not say
  // why. Any "\n" keeps the usual rule, so a stray "\r" in an LF or CR LF file (or "\r\r\n" endings) reads
  // as before. Returns the bytes available.
  std::size_t choose_terminator() {
    const std::size_t available = reader_.fill(reader_.capacity());
    const char* data = reader_.data();
    const bool cr_only = std::memchr(data, '\n', available) == nullptr && std::memchr(data, '\r', available);
    terminator_ = cr_only ? '\r' : '\n';
    return available;
  }

  ByteReader& reader_;
  std::uint64_t line_ = 0;
  char terminator_ = 0;  // 0 until the first line is read
};

inline bool is_blank(char c) {
  return c == ' ' || c == '\t' || c == '\r' || c == '\v' || c == '\f';
}

inline const char* skip_blanks(const char* p, const char* end) {
  while (p < end && is_blank(*p)) ++p;
  return p;
}

inline const char* token_end(const char* p, const char* end) {
  while (p < end && !is_blank(*p)) ++p;
  return p;
}

// The token at p (after blanks), for error messages, cut short when long.
inline std::string quote_token(const char* p, const char* end) {
  p = skip_blanks(p, end);
  const char* e = token_end(p, end);
  if (p == e) return "end of line";
  std::string token(p, static_cast<std::size_t>(std::min<std::ptrdiff_t>(e - p, 40)));
  for (char& c : token)
    if (static_cast<unsigned char>(c) < 0x20 || static_cast<unsigned char>(c) >= 0x7f) c = '?';
  return "'" + token + (e - p > 40 ? "...'" : "'");
}

enum class NumberStatus { ok, missing, malformed, not_finite, beyond_float };

// Parses one finite number token (Number: float or double) starting at p (after blanks); on success advances
// p past it. The token must end at a blank or at `end`: "1.5x" is malformed, not 1.5. Decimal text is rounded
// once, straight to Number. With `comment_ends`, a '#' ends the line's numbers too (OBJ's comments).
template <class Number>
inline NumberStatus parse_number(const char*& p, const char* end, Number& value, bool comment_ends = false) {
  static_assert(std::is_same_v<Number, float> || std::is_same_v<Number, double>);
  const char* start = skip_blanks(p, end);
  if (start == end || (comment_ends && *start == '#')) return NumberStatus::missing;
  const char* digits = (*start == '+' && start + 1 < end && start[1] != '-') ? start + 1 : start;
  const auto result = fast_float::from_chars(digits, end, value);
  if (result.ec != std::errc() ||
      (result.ptr < end && !is_blank(*result.ptr) && !(comment_ends && *result.ptr == '#')))
    return NumberStatus::malformed;
  if (!std::isfinite(value)) {
    if constexpr (std::is_same_v<Number, double>) return NumberStatus::not_finite;
    // A finite number too large for a float (1e39) is told apart from a written NaN or infinity.
    double wide = 0;
    fast_float::from_chars(digits, end, wide);
    return std::isfinite(wide) ? NumberStatus::beyond_float : NumberStatus::not_finite;
  }
  p = result.ptr;
  return NumberStatus::ok;
}

inline std::string describe(NumberStatus status, const char* p, const char* end) {
  switch (status) {
    case NumberStatus::missing:
      return "missing number";
    case NumberStatus::malformed:
      return "not a number: " + quote_token(p, end);
    case NumberStatus::not_finite:
      return "NaN or infinite number: " + quote_token(p, end);
    case NumberStatus::beyond_float:
      return "number beyond the float range (+-3.4e38), which positions are held in: " + quote_token(p, end);
    case NumberStatus::ok:
      break;
  }
  return "ok";
}

// Appends the shortest decimal text that reads back as exactly `value`. `out` needs 16 free bytes.
inline char* print_float(char* out, float value) {
  if (value == 0.0f) value = 0.0f;  // no "-0"
  return std::to_chars(out, out + 16, value).ptr;
}

// The same for a double: at most 24 characters.
inline char* print_double(char* out, double value) {
  if (value == 0.0) value = 0.0;
  return std::to_chars(out, out + 25, value).ptr;
}

// Writers refuse meshes they would write wrongly: faces pointing past the vertices, attribute arrays of the
// wrong length, coordinates that no reader would take back.
inline void check_writable(const std::string& path, const IndexedMesh& mesh) {
  const std::size_t n = mesh.positions.size();
  auto check_size = [&](std::size_t size, const char* what) {
    if (size != 0 && size != n) {
      throw Error(path, {},
                  std::string("cannot write: ") + what + " has " + std::to_string(size) + " entries for " +
                      std::to_string(n) + " vertices");
    }
  };
  check_size(mesh.normals.size(), "the normal array");
  check_size(mesh.colors.size(), "the color array");
  check_size(mesh.uvs.size(), "the uv array");
  auto check_finite = [&](const auto& values, const char* what) {
    for (std::size_t i = 0; i < values.size(); ++i) {
      if (!values[i].allFinite()) {
        throw Error(path, {}, "cannot write: vertex " + std::to_string(i) + " has a NaN or infinite " + what);
      }
    }
  };
  check_finite(mesh.positions, "coordinate");
  check_finite(mesh.normals, "normal");
  check_finite(mesh.uvs, "uv");
  for (std::size_t f = 0; f < mesh.triangles.size(); ++f) {
    for (Index v : mesh.triangles[f]) {
      if (v >= n) {
        throw Error(path, {},
                    "cannot write: face " + std::to_string(f) + " uses vertex " + std::to_string(v) +
                        " of only " + std::to_string(n));
      }
    }
  }
}

}  // namespace ocsimp::detail
