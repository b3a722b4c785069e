// The one error type of ocsimp: a file, a place in it, and a reason.
#pragma once

#include <cstdint>
#include <optional>
#include <stdexcept>
#include <string>

namespace ocsimp {

// Where in a file an error was found. Binary formats report byte offsets, text formats line numbers.
struct FilePosition {
  enum class Kind { none, byte, line };
  Kind kind = Kind::none;
  std::uint64_t value = 0;

  static FilePosition byte(std::uint64_t offset) { return {Kind::byte, offset}; }
  static FilePosition line(std::uint64_t number) { return {Kind::line, number}; }
};

// Thrown for bad input, failed output and impossible requests. what() is one line:
// "FILE: byte N: REASON", "FILE: line N: REASON" or "FILE: REASON" (or just REASON without a file), with
// any control character in it (a NUL or an escape quoted from the file) shown as '?'.
class Error : public std::runtime_error {
 public:
  Error(std::string file, FilePosition position, std::string reason);
  explicit Error(std::string reason) : Error({}, {}, std::move(reason)) {}

  const std::string& file() const { return file_; }
  const FilePosition& position() const { return position_; }
  const std::string& reason() const { return reason_; }

 private:
  std::string file_;
  FilePosition position_;
  std::string reason_;
};

// "1 triangle", "2 triangles": a count and its noun, for messages; `plural` where an added s is wrong.
inline std::string counted(std::uint64_t n, const std::string& noun, const std::string& plural = {}) {
  return std::to_string(n) + " " + (n == 1 ? noun : plural.empty() ? noun + "s" : plural);
}

}  // namespace ocsimp
