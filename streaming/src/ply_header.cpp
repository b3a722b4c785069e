#include "ply_header.h"

#include <cstring>
#include <string>
#include <unordered_set>

#include "ocsimp/core/error.h"

namespace ocsimp::detail {
namespace {

struct TypeName {
  std::string_view name;
  PlyType type;
};
constexpr TypeName kTypeNames[] = {
    {"char", PlyType::int8},       {"int8", PlyType::int8},       {"uchar", PlyType::uint8},
    {"uint8", PlyType::uint8},     {"short", PlyType::int16},     {"int16", PlyType::int16},
    {"ushort", PlyType::uint16},   {"uint16", PlyType::uint16},   {"int", PlyType::int32},
    {"int32", PlyType::int32},     {"uint", PlyType::uint32},     {"uint32", PlyType::uint32},
    {"float", PlyType::float32},   {"float32", PlyType::float32}, {"double", PlyType::float64},
    {"float64", PlyType::float64},
};

// A header line longer than this is not a header: the file is binary garbage or not PLY at all.
constexpr std::size_t kMaxHeaderLine = 1 << 16;

std::vector<std::string_view> split_words(std::string_view line) {
  std::vector<std::string_view> words;
  std::size_t i = 0;
  while (i < line.size()) {
    while (i < line.size() && (line[i] == ' ' || line[i] == '\t')) ++i;
    const std::size_t start = i;
    while (i < line.size() && line[i] != ' ' && line[i] != '\t') ++i;
    if (i > start) words.push_back(line.substr(start, i - start));
  }
  return words;
}

class HeaderParser {
 public:
  explicit HeaderParser(ByteReader& reader) : reader_(reader) {}

  PlyHeader parse() {
    PlyHeader header;
    // A UTF-8 byte order mark, as a text editor may put before an ASCII PLY, is not part of the first line.
    if (reader_.fill(3) >= 3 && std::memcmp(reader_.data(), "\xEF\xBB\xBF", 3) == 0) reader_.consume(3);
    // Lines that end in a CR alone would read as one long first line: say so rather than "no end_header".
    const std::size_t start = reader_.fill(5);
    if (start >= 4 && std::memcmp(reader_.data(), "ply\r", 4) == 0 &&
        (start == 4 || reader_.data()[4] != '\n')) {
      line_ = 1;
      fail("the lines end in a carriage return alone (classic Mac OS); PLY needs LF or CR LF line endings");
    }
    std::string_view line = next_line();
    // Trailing blanks are forgiven here as on every other header line.
    const std::size_t end = line.find_last_not_of(" \t");
    if (line.substr(0, end == std::string_view::npos ? 0 : end + 1) != "ply")
      fail("not a PLY file: the first line must be 'ply'");
    bool have_format = false;
    // Names seen, for the duplicate checks: a header of 300,000 elements took a minute when each new name
    // was compared with every earlier one.
    std::unordered_set<std::string> element_names, property_names;
    while (true) {
      if (reader_.at_end()) fail("the header ends without an end_header line");
      line = next_line();
      const std::vector<std::string_view> words = split_words(line);
      if (words.empty()) continue;
      const std::string_view keyword = words[0];
      if (keyword == "comment" || keyword == "obj_info") {
        if (keyword == "comment" && words.size() > 2 && words[1] == "TextureFile") {
          // The name is the rest of the line, which may hold blanks.
          std::string name(line.substr(static_cast<std::size_t>(words[2].data() - line.data())));
          name.erase(name.find_last_not_of(" \t\r") + 1);
          header.texture_files.push_back(std::move(name));
        }
        continue;
      }
      if (keyword == "end_header") {
        if (words.size() != 1) fail("unexpected text after end_header");
        break;
      }
      if (keyword == "format") {
        if (have_format) fail("a second format line");
        if (words.size() != 3) fail("expected 'format <ascii|binary_little_endian|binary_big_endian> 1.0'");
        if (words[1] == "ascii") {
          header.encoding = PlyEncoding::ascii;
        } else if (words[1] == "binary_little_endian") {
          header.encoding = PlyEncoding::binary_little_endian;
        } else if (words[1] == "binary_big_endian") {
          header.encoding = PlyEncoding::binary_big_endian;
        } else {
          fail("unknown format '" + std::string(words[1]) + "'");
        }
        if (words[2] != "1.0" && words[2] != "1")
          fail("unsupported PLY version '" + std::string(words[2]) + "'");
        have_format = true;
      } else if (keyword == "element") {
        if (!have_format) fail("an element before the format line");
        if (words.size() != 3) fail("expected 'element <name> <count>'");
        PlyElement element;
        element.name = words[1];
        element.count = parse_count(words[2]);
        element.header_line = line_;
        if (!element_names.insert(element.name).second) fail("a second element named '" + element.name + "'");
        property_names.clear();
        header.elements.push_back(std::move(element));
      } else if (keyword == "property") {
        if (header.elements.empty()) fail("a property outside any element");
        PlyProperty property;
        property.header_line = line_;
        if (words.size() >= 2 && words[1] == "list") {
          if (words.size() != 5) fail("expected 'property list <count type> <item type> <name>'");
          property.is_list = true;
          property.count_type = parse_type(words[2]);
          if (!ply_type_is_integer(property.count_type)) {
            fail("a list count must have an integer type, not " + std::string(words[2]));
          }
          property.type = parse_type(words[3]);
          property.name = words[4];
        } else {
          if (words.size() != 3) fail("expected 'property <type> <name>'");
          property.type = parse_type(words[1]);
          property.name = words[2];
        }
        PlyElement& element = header.elements.back();
        if (!property_names.insert(property.name).second) {
          fail("a second property named '" + property.name + "' in element '" + element.name + "'");
        }
        element.properties.push_back(std::move(property));
      } else {
        fail("unknown header keyword '" + std::string(keyword) + "'");
      }
    }
    if (!have_format) fail("the header has no format line");
    header.data_offset = reader_.offset();
    header.data_line = line_ + 1;
    return header;
  }

 private:
  // The next line without its line ending; the view lives until the next call.
  std::string_view next_line() {
    ++line_;
    const std::size_t available = reader_.fill(kMaxHeaderLine);
    const char* begin = reader_.data();
    const char* newline = static_cast<const char*>(std::memchr(begin, '\n', available));
    if (newline == nullptr) {
      if (available >= kMaxHeaderLine) fail("header line too long (binary data before end_header?)");
      // An end_header as the file's last line, without a line ending, ends a file without data.
      std::string_view last(begin, available);
      last = last.substr(0, last.find_last_not_of(" \t\r") + 1);
      if (last != "end_header") fail("the header ends without an end_header line");
    }
    std::size_t length = newline ? static_cast<std::size_t>(newline - begin) : available;
    reader_.consume(newline ? length + 1 : length);
    if (length > 0 && begin[length - 1] == '\r') --length;
    return std::string_view(begin, length);
  }

  std::uint64_t parse_count(std::string_view text) {
    if (!text.empty() && text[0] == '-') fail("negative element count " + std::string(text));
    std::uint64_t value = 0;
    if (text.empty()) fail("missing element count");
    for (char c : text) {
      if (c < '0' || c > '9') fail("element count '" + std::string(text) + "' is not a number");
      const std::uint64_t digit = static_cast<std::uint64_t>(c - '0');
      if (value > (UINT64_MAX - digit) / 10) fail("element count " + std::string(text) + " is absurd");
      value = value * 10 + digit;
    }
    return value;
  }

  PlyType parse_type(std::string_view name) {
    if (auto type = parse_ply_type(name)) return *type;
    fail("unsupported property type '" + std::string(name) + "'");
  }

  [[noreturn]] void fail(const std::string& reason) {
    throw Error(reader_.path(), FilePosition::line(line_), reason);
  }

  ByteReader& reader_;
  std::uint64_t line_ = 0;
};

}  // namespace

std::size_t ply_type_size(PlyType type) {
  switch (type) {
    case PlyType::int8:
    case PlyType::uint8:
      return 1;
    case PlyType::int16:
    case PlyType::uint16:
      return 2;
    case PlyType::int32:
    case PlyType::uint32:
    case PlyType::float32:
      return 4;
    case PlyType::float64:
      return 8;
  }
  return 0;
}

const char* ply_type_name(PlyType type) {
  switch (type) {
    case PlyType::int8:
      return "char";
    case PlyType::uint8:
      return "uchar";
    case PlyType::int16:
      return "short";
    case PlyType::uint16:
      return "ushort";
    case PlyType::int32:
      return "int";
    case PlyType::uint32:
      return "uint";
    case PlyType::float32:
      return "float";
    case PlyType::float64:
      return "double";
  }
  return "?";
}

std::optional<PlyType> parse_ply_type(std::string_view name) {
  for (const TypeName& entry : kTypeNames) {
    if (entry.name == name) return entry.type;
  }
  return std::nullopt;
}

std::optional<std::size_t> PlyElement::find(std::string_view property_name) const {
  for (std::size_t i = 0; i < properties.size(); ++i) {
    if (properties[i].name == property_name) return i;
  }
  return std::nullopt;
}

bool PlyElement::has_lists() const {
  for (const PlyProperty& property : properties) {
    if (property.is_list) return true;
  }
  return false;
}

std::size_t PlyElement::min_binary_size() const {
  std::size_t size = 0;
  for (const PlyProperty& property : properties) {
    size += ply_type_size(property.is_list ? property.count_type : property.type);
  }
  return size;
}

PlyHeader parse_ply_header(ByteReader& reader) {
  return HeaderParser(reader).parse();
}

}  // namespace ocsimp::detail
