// Sequential buffered reading of a file with read(2), tracking the byte offset for error messages.
// read(2) into one reused buffer rather than mmap: resident memory stays at the buffer size however large the
// file, and from page cache it runs at the speed of `cat`.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace ocsimp::detail {

class ByteReader {
 public:
  static constexpr std::size_t default_capacity = 4 << 20;

  explicit ByteReader(std::string path, std::size_t capacity = default_capacity);
  ~ByteReader();
  ByteReader(const ByteReader&) = delete;
  ByteReader& operator=(const ByteReader&) = delete;

  const std::string& path() const { return path_; }
  std::uint64_t file_size() const { return file_size_; }
  // Offset in the file of data().
  std::uint64_t offset() const { return window_offset_ + cursor_; }

  // Makes at least `count` bytes (count <= capacity) available from the cursor unless the file ends first;
  // returns how many are available.
  std::size_t fill(std::size_t count);
  const char* data() const { return buffer_.data() + cursor_; }
  std::size_t available() const { return end_ - cursor_; }
  void consume(std::size_t count) { cursor_ += count; }
  bool at_end() { return available() == 0 && fill(1) == 0; }
  std::size_t capacity() const { return buffer_.size(); }

  // Restarts from byte `offset` (for formats that need a second look, like a bounds pre-scan).
  void seek(std::uint64_t offset);

  // Reads up to `count` bytes at file offset `offset` into `out`, past the window and without moving it
  // (pread: several threads may call it at once). Returns the bytes read, fewer only where the file ends.
  std::size_t read_at(std::uint64_t offset, char* out, std::size_t count) const;

 private:
  std::string path_;
  int fd_ = -1;
  std::uint64_t file_size_ = 0;
  std::vector<char> buffer_;
  std::uint64_t window_offset_ = 0;  // file offset of buffer_[0]
  std::size_t cursor_ = 0;
  std::size_t end_ = 0;
  bool eof_ = false;
};

}  // namespace ocsimp::detail
