// PLY header parsing shared by the mesh reader and the cloud-file check (internal to common).
// Counts are parsed as plain non-negative integers and checked against the bytes the file holds
// before any element is read: a header that lies costs an error, never a loop or an allocation.
#pragma once
#include <cstdint>
#include <string>
#include <vector>

#include "cellsight/common/errors.hpp"

namespace cellsight::ply {

struct Property {
  std::string name, type, list_count_type;
  bool is_list = false;
};
struct Element {
  std::string name;
  size_t count = 0;
  std::vector<Property> props;
};
struct Header {
  std::string format;  ///< ascii | binary_little_endian | binary_big_endian
  std::vector<Element> elements;
  size_t end = 0;      ///< first byte of the body
};

/// Bytes of a PLY scalar type; ConfigError naming the file for an unknown one.
size_t typeSize(const std::string& t, const std::string& file);

/// Parses and checks the header of `data` (the whole file): magic, end_header, counts that are
/// integers, elements with properties, and counts the body can hold (binary: the smallest item
/// size times the count; ascii: one value per two bytes). ConfigError naming the file.
Header parse(const std::string& path, const std::string& data);

/// What the mesh and cloud readers take from a PLY body.
struct Body {
  std::vector<std::string> vertex_props;  ///< scalar properties of 'vertex', in file order
  std::vector<double> vertices;           ///< count x vertex_props.size(), row by row
  std::vector<std::vector<long>> faces;   ///< the vertex_indices (or vertex_index) list of each 'face'
};

/// Reads the body of `data` as `h` describes it (ascii or binary_little_endian; other elements
/// are read past). Every read is bounded by the file's size; lists longer than the rest of the
/// file and face indices beyond int range are refused. ConfigError naming the file.
Body readBody(const std::string& path, const std::string& data, const Header& h);

}  // namespace cellsight::ply
