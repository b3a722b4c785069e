// Output files that appear complete or not at all.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <string>
#include <string_view>
#include <vector>

namespace ocsimp {

// Buffered writer to a temporary file in the target's folder: unnamed (O_TMPFILE) where the file system has
// them, so that no way of dying leaves it behind, otherwise hidden. commit() flushes it, gives it a hidden
// name, closes it and renames it over the target; destruction without commit() (an exception, an early
// return) deletes the temporary. A SIGINT/SIGTERM/SIGHUP handler deletes every named temporary before the
// process dies. A path that is a
// symbolic link is written through: the target is the file at the end of its links, and they stay links.
// A path that exists as neither a regular file nor a folder (a device such as /dev/null, a FIFO,
// /dev/stdout on a pipe) is written directly, as a stream: no rename could replace it, and what was sent
// before a failure stays sent.
class AtomicFile {
 public:
  explicit AtomicFile(std::string path);
  ~AtomicFile();
  AtomicFile(const AtomicFile&) = delete;
  AtomicFile& operator=(const AtomicFile&) = delete;

  void write(const void* data, std::size_t size);
  void write(std::string_view text) { write(text.data(), text.size()); }
  // Space for `size` bytes in the buffer, to be filled by the caller and then accounted by advance(size).
  // Lets hot writers format straight into the buffer. `size` must not exceed buffer_capacity.
  char* reserve(std::size_t size);
  void advance(std::size_t size) { used_ += size; }
  std::uint64_t bytes_written() const { return flushed_ + used_; }
  void commit();
  // write(), reserve() and commit() after a commit, or after a failure closed the file, throw Error.

  const std::string& path() const { return path_; }
  static constexpr std::size_t buffer_capacity = 1 << 20;

 private:
  void check_open() const;
  void flush();

  std::string path_;         // as given, for messages
  std::string target_path_;  // what the rename replaces: path_ with its symbolic links followed
  std::string temp_path_;
  int fd_ = -1;
  std::vector<char> buffer_;
  std::size_t used_ = 0;
  std::uint64_t flushed_ = 0;
  bool committed_ = false;
  bool direct_ = false;   // writing straight to path_ (not a regular file), no temporary
  bool unnamed_ = false;  // an O_TMPFILE file, until commit() names it (from temp_path_, its Xs replaced)
};

// A complete output whose rename is still to come (see HeldCommits).
struct FinishedFile {
  std::string path, target_path, temp_path;
  int fd = -1;
  bool unnamed = false;
};

// While one is alive, AtomicFile::commit() (on any thread) completes its file but holds back the rename that
// makes it appear, so that a set of outputs (lod's levels and report) appears together or not at all.
// release() makes them appear, in the order they were committed; destruction without it deletes them, and a
// process that dies first leaves none (they are unnamed until then, or removed by the signal handler). One
// at a time: a second, while one is alive, throws Error. Files written directly (a device, a FIFO) are
// written at once.
class HeldCommits {
 public:
  HeldCommits();
  ~HeldCommits();
  HeldCommits(const HeldCommits&) = delete;
  HeldCommits& operator=(const HeldCommits&) = delete;
  void release();

 private:
  std::vector<FinishedFile> files_;
};

// Runs `work` with SIGINT, SIGTERM and SIGHUP held back (on any thread): the handler notes the signal, and
// the end of the outermost such call raises it again, which then deletes what temporaries are left and ends
// the process. Around renames into place, so that a set of outputs is either all there or none (a signal
// between a mesh's rename and its report's left the mesh alone), and no temporary is named without being
// registered for the handler.
void with_signals_deferred(const std::function<void()>& work);

// Throws the error that writing `path` would meet, before any work: creates and deletes a temporary beside
// it, or, for a path written directly (see AtomicFile), checks it is writable without opening it (opening a
// FIFO would wait for its reader, and closing it end that reader's input).
void check_writable(const std::string& path);

}  // namespace ocsimp
