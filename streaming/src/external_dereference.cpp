#include "ocsimp/streaming/external_dereference.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <optional>
#include <string_view>
#include <vector>

#include "byte_reader.h"
#include "formats.h"
#include "ocsimp/core/error.h"
#include "ocsimp/core/system.h"
#include "ply_header.h"

namespace ocsimp {
namespace {

static_assert(sizeof(Vec3f) == 12 && sizeof(Triangle) == 12);

// A position: what the budget counts per vertex of an OBJ, whose colors are not known up front.
constexpr std::uint64_t kVertexBytes = 12;
// Enough partitions for a budget 64 times smaller than the vertex array; a smaller budget is exceeded (each
// partition then holds 1/64 of the vertices) rather than the time growing with it: each partition is one
// more scan of the faces file. With up to 4096 partitions, a 3 M-triangle scan under a 1 KiB limit took
// 4096 scans of its 36 MB faces file, and ran for minutes.
constexpr std::uint64_t kMaxPartitions = 64;
constexpr std::size_t kBufferBytes = 1 << 20;
constexpr std::size_t kMinBufferBytes = 4096;
constexpr std::size_t kSpoolBlock = 1 << 20;  // vertices

// A spooled vertex and a dereferenced corner are the same record: the position, then each attribute the
// reader delivers (a PLY's normals, colors and texture coordinates), packed.
struct RecordLayout {
  bool normals = false, colors = false, uvs = false;

  static RecordLayout of(const VertexChunk& chunk) {
    return {!chunk.normals.empty(), !chunk.colors.empty(), !chunk.uvs.empty()};
  }
  bool operator==(const RecordLayout&) const = default;
  std::size_t bytes() const { return vertex_bytes(normals, colors, uvs); }
  // Vertex i of `chunk` into `out` (bytes() of room).
  void pack(const VertexChunk& chunk, std::size_t i, std::uint8_t* out) const {
    out = put(out, chunk.positions[i]);
    if (normals) out = put(out, chunk.normals[i]);
    if (colors) out = put(out, chunk.colors[i]);
    if (uvs) put(out, chunk.uvs[i]);
  }
  // A vertex from `in`, appended to `mesh`'s arrays.
  void unpack(const std::uint8_t* in, IndexedMesh& mesh) const {
    in = get(in, mesh.positions.emplace_back());
    if (normals) in = get(in, mesh.normals.emplace_back());
    if (colors) in = get(in, mesh.colors.emplace_back());
    if (uvs) get(in, mesh.uvs.emplace_back());
  }
  // Corner k of the batch's last triangle from `in`.
  void unpack(const std::uint8_t* in, TriangleBatch& batch, int k) const {
    in = get(in, batch.corners.back()[k]);
    if (normals) in = get(in, batch.corner_normals.back()[k]);
    if (colors) in = get(in, batch.corner_colors.back()[k]);
    if (uvs) get(in, batch.corner_uvs.back()[k]);
  }
  // Room in `batch` for one more triangle's corners.
  void grow(TriangleBatch& batch) const {
    batch.corners.emplace_back();
    if (normals) batch.corner_normals.emplace_back();
    if (colors) batch.corner_colors.emplace_back();
    if (uvs) batch.corner_uvs.emplace_back();
  }

 private:
  template <class T>
  static std::uint8_t* put(std::uint8_t* out, const T& value) {
    std::memcpy(out, &value, sizeof(T));
    return out + sizeof(T);
  }
  template <class T>
  static const std::uint8_t* get(const std::uint8_t* in, T& value) {
    std::memcpy(static_cast<void*>(&value), in, sizeof(T));  // Eigen vectors of floats: plain bytes
    return in + sizeof(T);
  }
};
static_assert(sizeof(Color) == 4 && sizeof(Vec2f) == 8);

std::string temp_dir() {
  const char* dir = std::getenv("TMPDIR");
  return dir != nullptr && *dir != 0 ? dir : "/tmp";
}

// A temporary file without a name: created under TMPDIR and unlinked at once, so it is gone with its
// descriptor however the process ends (an exception, a signal, SIGKILL).
class TempFile {
 public:
  TempFile() {
    std::string name = temp_dir() + "/ocsimp-deref-XXXXXX";
    fd_ = ::mkstemp(name.data());
    if (fd_ < 0) fail("creating", errno);
    ::unlink(name.c_str());
  }
  ~TempFile() {
    if (fd_ >= 0) ::close(fd_);
  }
  TempFile(const TempFile&) = delete;
  TempFile& operator=(const TempFile&) = delete;

  void write_at(std::uint64_t offset, const void* data, std::size_t size) const {
    const char* p = static_cast<const char*>(data);
    while (size > 0) {
      const ssize_t n = ::pwrite(fd_, p, size, static_cast<off_t>(offset));
      if (n < 0) {
        if (errno == EINTR) continue;
        fail("writing", errno);
      }
      p += n;
      size -= static_cast<std::size_t>(n);
      offset += static_cast<std::uint64_t>(n);
    }
  }
  void read_at(std::uint64_t offset, void* data, std::size_t size) const {
    char* p = static_cast<char*>(data);
    while (size > 0) {
      const ssize_t n = ::pread(fd_, p, size, static_cast<off_t>(offset));
      if (n < 0) {
        if (errno == EINTR) continue;
        fail("reading", errno);
      }
      if (n == 0) fail("reading past the end of", 0);
      p += n;
      size -= static_cast<std::size_t>(n);
      offset += static_cast<std::uint64_t>(n);
    }
  }

  // Reserves `size` bytes on disk, so that a folder without the room fails here, before the work that
  // would fill it, rather than at the end (a billion-triangle scan: 36 GB of corners, after a minute).
  // File systems that cannot reserve (EOPNOTSUPP) are written as before.
  void reserve(std::uint64_t size, const std::string& what) const {
    if (size == 0) return;
    int error;
    do {
      error = ::fallocate(fd_, 0, 0, static_cast<off_t>(size)) == 0 ? 0 : errno;
    } while (error == EINTR);
    if (error == 0 || error == EOPNOTSUPP || error == ENOSYS) return;
    throw_system_error("out-of-core reading needs " + format_bytes(size) + " of temporary space for " + what +
                           " and could not reserve it",
                       error);
  }

 private:
  [[noreturn]] static void fail(const char* what, int error) {
    throw_system_error(std::string("out-of-core reading: ") + what + " a temporary file failed", error);
  }
  // `reason`, then the system's word for `error` (none for 0) and, for a full disk, the way out.
  [[noreturn]] static void throw_system_error(std::string reason, int error) {
    if (error != 0) reason += std::string(": ") + std::strerror(error);
    if (error == ENOSPC || error == EFBIG) reason += " (set TMPDIR to a folder on a disk with more room)";
    throw Error(temp_dir(), {}, reason);
  }

  int fd_ = -1;
};

// Appends records of `record` bytes from `offset` on through a buffer of about `buffer_bytes`.
class RecordWriter {
 public:
  RecordWriter(const TempFile& file, std::uint64_t offset, std::size_t record, std::size_t buffer_bytes)
      : file_(&file),
        offset_(offset),
        record_(record),
        buffer_(std::max(buffer_bytes / record, std::size_t{1}) * record) {}
  // Room for the next record, which the caller fills.
  std::uint8_t* push() {
    if (used_ == buffer_.size()) flush();
    std::uint8_t* slot = buffer_.data() + used_;
    used_ += record_;
    return slot;
  }
  void flush() {
    if (used_ == 0) return;
    file_->write_at(offset_, buffer_.data(), used_);
    offset_ += used_;
    used_ = 0;
  }

 private:
  const TempFile* file_;
  std::uint64_t offset_;
  std::size_t record_;
  std::vector<std::uint8_t> buffer_;
  std::size_t used_ = 0;
};

// Reads `count` records of `record` bytes from `offset` on through a buffer of about `buffer_bytes`.
class RecordReader {
 public:
  RecordReader(const TempFile& file, std::uint64_t offset, std::uint64_t count, std::size_t record,
               std::size_t buffer_bytes)
      : file_(&file),
        offset_(offset),
        left_(count),
        record_(record),
        capacity_(std::max(buffer_bytes / record, std::size_t{1})) {}
  const std::uint8_t* next() {
    if (cursor_ == end_) refill();
    const std::uint8_t* record = buffer_.data() + cursor_;
    cursor_ += record_;
    return record;
  }

 private:
  void refill() {
    if (left_ == 0)
      throw Error(temp_dir(), {}, "out-of-core reading: a temporary file holds fewer records than written");
    const auto n = static_cast<std::size_t>(std::min<std::uint64_t>(left_, capacity_));
    buffer_.resize(n * record_);
    file_->read_at(offset_, buffer_.data(), n * record_);
    offset_ += n * record_;
    left_ -= n;
    cursor_ = 0;
    end_ = n * record_;
  }

  const TempFile* file_;
  std::uint64_t offset_;
  std::uint64_t left_;
  std::size_t record_;
  std::size_t capacity_;  // records
  std::vector<std::uint8_t> buffer_;
  std::size_t cursor_ = 0, end_ = 0;
};

// The faces file holds each vertex id as the zigzag varint of its difference from the one before: a mesh's
// faces mostly use vertices stored near each other, so an id takes one or two bytes instead of four (a
// 10^9-triangle scan's faces: 12 GB as plain ids, about 5 GB coded). The file is read once per partition
// and that disk space is what decides whether an input can be dereferenced at all.
constexpr std::size_t kMaxCodedTriangle = 15;  // three 5-byte varints

class FaceWriter {
 public:
  FaceWriter(const TempFile& file, std::size_t buffer_bytes)
      : file_(&file), buffer_(std::max(buffer_bytes, 2 * kMaxCodedTriangle)) {}
  void push(const Triangle& t) {
    if (used_ + kMaxCodedTriangle > buffer_.size()) flush();
    for (Index v : t) {
      const auto delta = static_cast<std::uint32_t>(v - previous_);
      previous_ = v;
      // Zigzag: small differences of either sign become small numbers.
      std::uint32_t z = (delta << 1) ^ static_cast<std::uint32_t>(-static_cast<std::int32_t>(delta >> 31));
      while (z >= 0x80) {
        buffer_[used_++] = static_cast<std::uint8_t>(z | 0x80);
        z >>= 7;
      }
      buffer_[used_++] = static_cast<std::uint8_t>(z);
    }
  }
  void flush() {
    file_->write_at(bytes_, buffer_.data(), used_);
    bytes_ += used_;
    used_ = 0;
  }
  std::uint64_t bytes() const { return bytes_ + used_; }

 private:
  const TempFile* file_;
  std::vector<std::uint8_t> buffer_;
  std::size_t used_ = 0;
  std::uint64_t bytes_ = 0;
  Index previous_ = 0;
};

class FaceReader {
 public:
  FaceReader(const TempFile& file, std::uint64_t bytes, std::size_t buffer_bytes)
      : file_(&file), left_(bytes), buffer_(std::max(buffer_bytes, 2 * kMaxCodedTriangle)) {}
  Triangle next() {
    if (end_ - cursor_ < kMaxCodedTriangle) refill();
    Triangle t;
    for (Index& v : t) {
      std::uint32_t z = 0;
      for (int shift = 0;; shift += 7) {
        if (cursor_ == end_ || shift > 28) corrupt();
        const std::uint8_t byte = buffer_[cursor_++];
        z |= static_cast<std::uint32_t>(byte & 0x7F) << shift;
        if (byte < 0x80) break;
      }
      previous_ += (z >> 1) ^ (0u - (z & 1u));
      v = previous_;
    }
    return t;
  }

 private:
  void refill() {
    std::copy(buffer_.begin() + static_cast<std::ptrdiff_t>(cursor_),
              buffer_.begin() + static_cast<std::ptrdiff_t>(end_), buffer_.begin());
    end_ -= cursor_;
    cursor_ = 0;
    const auto n = static_cast<std::size_t>(std::min<std::uint64_t>(left_, buffer_.size() - end_));
    file_->read_at(offset_, buffer_.data() + end_, n);
    offset_ += n;
    left_ -= n;
    end_ += n;
  }
  [[noreturn]] static void corrupt() {
    throw Error(temp_dir(), {}, "out-of-core reading: a temporary file holds fewer records than written");
  }

  const TempFile* file_;
  std::uint64_t offset_ = 0;
  std::uint64_t left_;
  std::vector<std::uint8_t> buffer_;
  std::size_t cursor_ = 0, end_ = 0;
  Index previous_ = 0;
};

// Where the reader's vertices go: memory while they fit the budget, a temporary file once they do not.
class VertexSpool {
 public:
  explicit VertexSpool(std::uint64_t budget_bytes) : budget_(budget_bytes) {}

  void add(const VertexChunk& chunk) {
    if (count_ == 0 && !file_) {
      // The first chunk says what the records carry; held in memory, they take the budget's bytes.
      layout_ = RecordLayout::of(chunk);
      capacity_ = std::max<std::uint64_t>(budget_ / layout_.bytes(), 1);
    } else if (!(RecordLayout::of(chunk) == layout_)) {
      throw Error(temp_dir(), {}, "out-of-core reading: the reader changed the attributes it delivers");
    }
    const std::size_t record = layout_.bytes();
    const std::size_t count = chunk.positions.size();
    count_ += count;
    if (!file_ && count_ <= capacity_) {
      // In blocks, not one growing vector: its reallocation would hold the old and the new array at once,
      // up to 1.5x the budget.
      for (std::size_t i = 0; i < count; ++i) {
        if (blocks_.empty() || blocks_.back().size() == kSpoolBlock * record) {
          blocks_.emplace_back();
          blocks_.back().reserve(kSpoolBlock * record);
        }
        std::vector<std::uint8_t>& block = blocks_.back();
        block.resize(block.size() + record);
        layout_.pack(chunk, i, block.data() + block.size() - record);
      }
      return;
    }
    if (!file_) {
      file_.emplace();
      std::uint64_t offset = 0;
      for (std::vector<std::uint8_t>& block : blocks_) {
        file_->write_at(offset, block.data(), block.size());
        offset += block.size();
        block = {};
      }
      blocks_ = {};
      writer_.emplace(*file_, offset, record, kBufferBytes);
    }
    for (std::size_t i = 0; i < count; ++i) layout_.pack(chunk, i, writer_->push());
  }

  // The vertices held in memory, freed (they fit after all; the plain reader loads them again).
  void release() { blocks_ = {}; }
  // The vertices held in memory, moved to `mesh`'s arrays a block at a time (they fit after all).
  void unpack_into(IndexedMesh& mesh) {
    mesh.positions.reserve(count_);
    if (layout_.normals) mesh.normals.reserve(count_);
    if (layout_.colors) mesh.colors.reserve(count_);
    if (layout_.uvs) mesh.uvs.reserve(count_);
    const std::size_t record = layout_.bytes();
    for (std::vector<std::uint8_t>& block : blocks_) {
      for (std::size_t at = 0; at < block.size(); at += record) layout_.unpack(block.data() + at, mesh);
      block = {};
    }
    blocks_ = {};
  }
  bool spilled() const { return file_.has_value(); }
  std::uint64_t count() const { return count_; }
  const RecordLayout& layout() const { return layout_; }
  // The file with every vertex, once the reader is done.
  const TempFile& file() {
    writer_->flush();
    return *file_;
  }

 private:
  std::uint64_t budget_;
  RecordLayout layout_;
  std::uint64_t capacity_ = 1;  // records
  std::uint64_t count_ = 0;
  std::vector<std::vector<std::uint8_t>> blocks_;
  std::optional<TempFile> file_;
  std::optional<RecordWriter> writer_;
};

class DereferencedStream final : public TriangleStream {
 public:
  DereferencedStream(const std::string& path, FileFormat format, const ReadOptions& options)
      : path_(path),
        capacity_(std::max<std::size_t>(options.batch_capacity, 1)),
        budget_(std::max<std::uint64_t>(options.memory_budget, kVertexBytes)),
        progress_(options.progress),
        spool_(budget_) {
    ReadOptions inner_options = options;
    inner_options.memory_budget = 0;
    inner_options.vertex_sink = [this](const VertexChunk& chunk) { spool_.add(chunk); };
    inner_ = format == FileFormat::ply ? detail::open_ply_stream(path, inner_options)
                                       : detail::open_obj_stream(path, inner_options);
    bounds_ = inner_->bounds();
    vertices_.origin = inner_->vertices().origin;  // the spooled positions and corners are relative to it
    vertex_count_ = spool_.count();
    bytes_total_ = inner_->bytes_total();
    if (!spool_.spilled() && inner_->attributes_left_out().empty()) {
      // They fit after all (OBJ says no count up front), and the reader left nothing out: its records are the
      // vertex array, and it goes on with the faces.
      spool_.unpack_into(vertices_);
      vertices_from_spool_ = true;
      // The reader kept no positions to split its polygons by: it reads this stream's (or wherever a
      // consumer of scratch_vertices() says they went).
      inner_->set_position_source([this](Index v) { return position(v); });
      return;
    }
    if (!spool_.spilled()) {
      // They fit after all, but the reader above kept positions and colors only, so the file is read again
      // by the plain one, which keeps its normals and texture coordinates: a second read of a file that
      // fits, where dropping them went unsaid. Its progress is a phase of its own, not the first one over.
      spool_.release();
      ReadOptions plain = options;
      plain.memory_budget = 0;
      plain.vertex_sink = nullptr;
      if (options.progress) {
        plain.progress = [progress = options.progress](std::string_view phase, std::uint64_t done,
                                                       std::uint64_t total) {
          progress(phase == "read" ? "read again" : phase, done, total);
        };
      }
      inner_ = open_triangle_stream(path, plain);
      inner_->set_position_source([this](Index v) { return position(v); });  // as above
      return;
    }
    left_out_ = inner_->attributes_left_out();
    faces_file_.emplace();
    corners_file_.emplace();
    drain_faces();
    inner_.reset();
    const std::size_t record = spool_.layout().bytes();
    corners_file_->reserve(
        3 * triangles_ * record,
        (record == sizeof(Vec3f) ? "the positions of " : "the positions and attributes of ") +
            std::to_string(3 * triangles_) + " corners");
    resolve_partitions();
  }

  bool next(TriangleBatch& batch) override {
    if (inner_) return inner_->next(batch);
    batch.clear();
    if (emitted_ == triangles_) return false;
    const RecordLayout& layout = spool_.layout();
    if (!face_reader_) {
      face_reader_.emplace(*faces_file_, face_bytes_, kBufferBytes);
      const std::size_t buffer = buffer_bytes();
      corner_readers_.reserve(partitions_);
      for (std::size_t p = 0; p < partitions_; ++p)
        corner_readers_.emplace_back(*corners_file_, region_offset_[p], corner_counts_[p], layout.bytes(),
                                     buffer);
    }
    while (batch.corners.size() < capacity_ && emitted_ < triangles_) {
      const Triangle t = face_reader_->next();
      layout.grow(batch);
      for (int k = 0; k < 3; ++k) layout.unpack(corner_readers_[t[k] / part_size_].next(), batch, k);
      ++emitted_;
    }
    return true;
  }

  const IndexedMesh& vertices() const override {
    return inner_ && !vertices_from_spool_ ? inner_->vertices() : vertices_;
  }
  Box3 bounds() override { return inner_ ? inner_->bounds() : bounds_; }
  std::string attributes_left_out() const override { return left_out_; }
  std::uint64_t triangles_hint() const override { return inner_ ? inner_->triangles_hint() : triangles_; }
  std::uint64_t bytes_read() const override {
    if (inner_) return inner_->bytes_read();
    return triangles_ == 0
               ? bytes_total_
               : static_cast<std::uint64_t>(static_cast<double>(bytes_total_) *
                                            static_cast<double>(emitted_) / static_cast<double>(triangles_));
  }
  std::uint64_t bytes_total() const override { return bytes_total_; }
  const std::string& path() const override { return path_; }

  bool out_of_core() const { return !inner_; }
  std::uint64_t vertex_count() const { return vertex_count_; }
  std::size_t partitions() const { return partitions_; }
  // Every partition's region is read at once: their buffers share the budget.
  std::size_t buffer_bytes() const {
    return static_cast<std::size_t>(
        std::clamp<std::uint64_t>(budget_ / (partitions_ + 1), kMinBufferBytes, kBufferBytes));
  }

 private:
  // The faces, once, to the index file; counts the corners of each partition.
  void drain_faces() {
    part_size_ =
        std::max<std::uint64_t>({budget_ / spool_.layout().bytes(),
                                 (vertex_count_ + kMaxPartitions - 1) / kMaxPartitions, std::uint64_t{1}});
    partitions_ = static_cast<std::size_t>((vertex_count_ + part_size_ - 1) / part_size_);
    corner_counts_.assign(partitions_, 0);
    FaceWriter writer(*faces_file_, kBufferBytes);
    TriangleBatch batch;
    while (inner_->next(batch)) {
      for (const Triangle& t : batch.triangles) {
        for (Index v : t) {
          // The readers check indices against the file's count; this guards the partition arithmetic.
          if (v >= vertex_count_) {
            throw Error(path_, {},
                        "vertex index " + std::to_string(v) + " is out of range (" +
                            std::to_string(vertex_count_) + " vertices)");
          }
          ++corner_counts_[v / part_size_];
        }
        writer.push(t);
      }
      triangles_ += batch.triangles.size();
    }
    writer.flush();
    face_bytes_ = writer.bytes();
  }

  // Each partition's vertices in memory, one scan of the index file, its corners' positions to its region.
  void resolve_partitions() {
    const std::size_t record = spool_.layout().bytes();
    region_offset_.assign(partitions_, 0);
    for (std::size_t p = 1; p < partitions_; ++p)
      region_offset_[p] = region_offset_[p - 1] + corner_counts_[p - 1] * record;
    const TempFile& vertex_file = spool_.file();
    std::vector<std::uint8_t> part;
    for (std::size_t p = 0; p < partitions_; ++p) {
      const std::uint64_t first = p * part_size_;
      const std::uint64_t size = std::min(part_size_, vertex_count_ - first);
      part.resize(static_cast<std::size_t>(size * record));
      vertex_file.read_at(first * record, part.data(), part.size());
      FaceReader faces(*faces_file_, face_bytes_, kBufferBytes);
      RecordWriter corners(*corners_file_, region_offset_[p], record, kBufferBytes);
      for (std::uint64_t f = 0; f < triangles_; ++f) {
        for (Index v : faces.next()) {
          const std::uint64_t local = v - first;  // wraps past the end for ids below `first`
          if (local < size) std::memcpy(corners.push(), part.data() + local * record, record);
        }
      }
      corners.flush();
      report(progress_, "dereference", p + 1, partitions_);
    }
  }

  std::string path_;
  std::size_t capacity_;
  std::uint64_t budget_;
  ProgressFn progress_;
  VertexSpool spool_;
  // Once constructed: the plain reader when the vertices fit, null when the faces are on disk (while
  // constructing, the reader in sink mode).
  std::unique_ptr<TriangleStream> inner_;
  std::string left_out_;  // what the sink-mode reader left out (TriangleStream::attributes_left_out)
  IndexedMesh vertices_;  // out of core: its origin only; or the spooled vertices when they fit after all
  bool vertices_from_spool_ = false;
  Box3 bounds_;
  std::uint64_t vertex_count_ = 0;
  std::uint64_t bytes_total_ = 0;

  std::optional<TempFile> faces_file_;  // the faces' vertex ids, coded (FaceWriter)
  std::uint64_t face_bytes_ = 0;
  std::optional<TempFile> corners_file_;  // corner records, grouped by the partition of their vertex
  std::uint64_t triangles_ = 0;
  std::uint64_t part_size_ = 1;
  std::size_t partitions_ = 0;
  std::vector<std::uint64_t> corner_counts_;
  std::vector<std::uint64_t> region_offset_;

  std::optional<FaceReader> face_reader_;
  std::vector<RecordReader> corner_readers_;
  std::uint64_t emitted_ = 0;
};

}  // namespace

std::unique_ptr<TriangleStream> open_dereferenced_stream(const std::string& path,
                                                         const ReadOptions& options) {
  const FileFormat format = detect_format(path);
  if (format != FileFormat::ply && format != FileFormat::obj) {
    ReadOptions plain = options;
    plain.memory_budget = 0;
    return open_triangle_stream(path, plain);
  }
  return std::make_unique<DereferencedStream>(path, format, options);
}

bool dereferenced_out_of_core(const TriangleStream& stream) {
  const auto* dereferenced = dynamic_cast<const DereferencedStream*>(&stream);
  return dereferenced != nullptr && dereferenced->out_of_core();
}

std::uint64_t dereferenced_vertex_count(const TriangleStream& stream) {
  if (!dereferenced_out_of_core(stream)) return 0;
  return dynamic_cast<const DereferencedStream&>(stream).vertex_count();
}

std::uint64_t dereference_buffer_bytes(const TriangleStream& stream) {
  if (!dereferenced_out_of_core(stream)) return 0;
  const auto& dereferenced = dynamic_cast<const DereferencedStream&>(stream);
  return dereferenced.partitions() * dereferenced.buffer_bytes() + kBufferBytes;  // and the faces' reader
}

namespace detail {

std::unique_ptr<TriangleStream> open_within_budget(const std::string& path, FileFormat format,
                                                   const ReadOptions& options) {
  if (format == FileFormat::ply) {
    // The header says how many vertices there are and what each holds; a header that does not parse is left
    // to the reader to report.
    std::uint64_t vertices = 0, bytes = kVertexBytes;
    try {
      ByteReader reader(path, 1 << 16);
      const PlyHeader header = parse_ply_header(reader);
      for (const PlyElement& element : header.elements) {
        if (element.name == "vertex") {
          vertices = element.count;
          bytes = ply_vertex_bytes(path, element);
        }
      }
    } catch (const Error&) {
      return nullptr;
    }
    if (vertices <= options.memory_budget / bytes) return nullptr;
    return std::make_unique<DereferencedStream>(path, format, options);
  }
  if (format == FileFormat::obj) {
    // No count up front: a vertex line takes at least 8 bytes ("v 0 0 0\n"), so a file that small cannot
    // exceed the budget; otherwise the spool decides once it has seen the vertices.
    ByteReader reader(path, 1 << 12);
    if (reader.file_size() / 8 * kVertexBytes <= options.memory_budget) return nullptr;
    return std::make_unique<DereferencedStream>(path, format, options);
  }
  return nullptr;
}

}  // namespace detail
}  // namespace ocsimp
