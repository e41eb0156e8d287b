#include "ply_header.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <sstream>

namespace cellsight::ply {

size_t typeSize(const std::string& t, const std::string& file) {
  if (t == "char" || t == "uchar" || t == "int8" || t == "uint8") return 1;
  if (t == "short" || t == "ushort" || t == "int16" || t == "uint16") return 2;
  if (t == "int" || t == "uint" || t == "float" || t == "int32" || t == "uint32" || t == "float32") return 4;
  if (t == "double" || t == "float64") return 8;
  throw ConfigError(file + ": PLY property type '" + t + "' is not supported");
}

Header parse(const std::string& path, const std::string& data) {
  if (data.empty()) throw ConfigError(path + ": the file is empty");
  if (data.rfind("ply", 0) != 0) throw ConfigError(path + ": not a PLY file (no 'ply' magic)");
  const size_t end_pos = data.find("end_header");
  if (end_pos == std::string::npos || end_pos > (1u << 20))
    throw ConfigError(path + ": PLY header has no end_header (within its first MB)");
  Header h;
  std::istringstream header(data.substr(0, end_pos + 10));
  std::string line;
  std::getline(header, line);
  while (std::getline(header, line)) {
    if (!line.empty() && line.back() == '\r') line.pop_back();
    std::istringstream ls(line);
    std::string word;
    ls >> word;
    if (word == "format") {
      ls >> h.format;
    } else if (word == "element") {
      Element e;
      std::string count;
      ls >> e.name >> count;
      if (count.empty() || count.size() > 15 || count.find_first_not_of("0123456789") != std::string::npos)
        throw ConfigError(path + ": PLY element '" + e.name + "' has count '" + count + "', not a count");
      e.count = std::stoull(count);
      h.elements.push_back(e);
    } else if (word == "property") {
      if (h.elements.empty()) throw ConfigError(path + ": PLY property before any element");
      Property p;
      ls >> p.type;
      if (p.type == "list") {
        p.is_list = true;
        ls >> p.list_count_type >> p.type;
        typeSize(p.list_count_type, path);
      }
      typeSize(p.type, path);
      ls >> p.name;
      h.elements.back().props.push_back(p);
    } else if (word == "end_header") {
      break;
    }
  }
  // the body starts after the end_header line
  const size_t nl = data.find('\n', end_pos);
  h.end = nl == std::string::npos ? data.size() : nl + 1;
  if (h.format != "ascii" && h.format != "binary_little_endian" && h.format != "binary_big_endian")
    throw ConfigError(path + ": PLY format '" + h.format + "' is not a PLY format");
  const uint64_t body = data.size() - h.end;
  uint64_t need = 0;  // bytes (binary) or values (ascii) the counts need at the least
  for (const auto& e : h.elements) {
    if (e.count > 0 && e.props.empty())
      throw ConfigError(path + ": PLY element '" + e.name + "' has " + std::to_string(e.count) + " items but no properties");
    uint64_t item = 0;
    for (const auto& p : e.props)
      item += h.format == "ascii" ? 1 : (p.is_list ? typeSize(p.list_count_type, path) : typeSize(p.type, path));
    if (item > 0 && e.count > (body + 1) / item) {
      throw ConfigError(path + ": PLY element '" + e.name + "' claims " + std::to_string(e.count) +
                        " items, more than the file's " + std::to_string(body) + " body bytes can hold");
    }
    need += e.count * item;
  }
  const uint64_t can = h.format == "ascii" ? (body + 1) / 2 : body;
  if (need > can)
    throw ConfigError(path + ": PLY header claims more data than the file's " + std::to_string(body) + " body bytes hold");
  return h;
}

namespace {

double readBinary(const char* p, const std::string& t) {
  if (t == "char" || t == "int8") return static_cast<double>(*reinterpret_cast<const int8_t*>(p));
  if (t == "uchar" || t == "uint8") return *reinterpret_cast<const uint8_t*>(p);
  int16_t s16;
  uint16_t u16;
  int32_t s32;
  uint32_t u32;
  float f;
  double d;
  if (t == "short" || t == "int16") return std::memcpy(&s16, p, 2), s16;
  if (t == "ushort" || t == "uint16") return std::memcpy(&u16, p, 2), u16;
  if (t == "int" || t == "int32") return std::memcpy(&s32, p, 4), s32;
  if (t == "uint" || t == "uint32") return std::memcpy(&u32, p, 4), u32;
  if (t == "float" || t == "float32") return std::memcpy(&f, p, 4), f;
  return std::memcpy(&d, p, 8), d;
}

}  // namespace

Body readBody(const std::string& path, const std::string& data, const Header& h) {
  if (h.format != "ascii" && h.format != "binary_little_endian") {
    throw ConfigError(path + ": PLY format '" + h.format + "' not supported (use ascii or binary_little_endian)");
  }
  Body out;
  const bool ascii = h.format == "ascii";
  std::istringstream body(ascii ? data.substr(h.end) : std::string());
  size_t pos = h.end;
  // the next value of `type`, from the text or the bytes; `part` names what is truncated
  auto value = [&](const std::string& type, const char* part) {
    double v = 0;
    if (ascii) {
      if (!(body >> v)) throw ConfigError(path + ": PLY " + part + " is truncated");
      return v;
    }
    const size_t size = typeSize(type, path);
    if (pos + size > data.size()) throw ConfigError(path + ": PLY " + part + " is truncated");
    v = readBinary(data.data() + pos, type);
    pos += size;
    return v;
  };
  for (const auto& e : h.elements) {
    const bool vertex = e.name == "vertex", face = e.name == "face";
    if (vertex) {
      for (const auto& p : e.props)
        if (!p.is_list) out.vertex_props.push_back(p.name);
      out.vertices.reserve(e.count * out.vertex_props.size());  // parse() checked the body holds them
    }
    for (size_t k = 0; k < e.count; ++k) {
      std::vector<long> list;
      for (const auto& p : e.props) {
        if (p.is_list) {
          const double n = value(p.list_count_type, "list");
          // a list length the rest of the file cannot hold is a lie, not a long loop
          if (!(n >= 0) || n > static_cast<double>(data.size() - std::min(data.size(), pos)))
            throw ConfigError(path + ": PLY list of " + std::to_string(n) + " items in element '" + e.name +
                              "' runs past the end of the file");
          const bool indices = face && (p.name == "vertex_indices" || p.name == "vertex_index");
          for (long j = 0; j < static_cast<long>(n); ++j) {
            const double v = value(p.type, "list");
            if (indices) {
              if (!(std::abs(v) < 2147483647.0)) throw ConfigError(path + ": PLY face index " + std::to_string(v) + " out of range");
              list.push_back(static_cast<long>(v));
            }
          }
        } else {
          const double v = value(p.type, "body");
          if (vertex) out.vertices.push_back(v);
        }
      }
      if (face) out.faces.push_back(std::move(list));
    }
  }
  return out;
}

}  // namespace cellsight::ply
