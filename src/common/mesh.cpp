#include "cellsight/common/mesh.hpp"

#include "ply_header.hpp"

#include <algorithm>
#include <array>
#include <limits>
#include <cmath>
#include <cstring>
#include <fstream>
#include <map>
#include <sstream>
#include <unordered_map>

#include "cellsight/common/errors.hpp"
#include "cellsight/common/file_io.hpp"

namespace cellsight {

void TriangleMesh::append(const TriangleMesh& other, const Eigen::Isometry3d& T) {
  const int offset = static_cast<int>(vertices.size());
  const Eigen::Isometry3f Tf = T.cast<float>();
  for (const auto& v : other.vertices) vertices.push_back(Tf * v);
  for (const auto& f : other.faces) faces.push_back(f + Eigen::Vector3i::Constant(offset));
}

void TriangleMesh::transform(const Eigen::Isometry3d& T) {
  const Eigen::Isometry3f Tf = T.cast<float>();
  for (auto& v : vertices) v = Tf * v;
}

Eigen::AlignedBox3f TriangleMesh::bounds() const {
  Eigen::AlignedBox3f box;
  for (const auto& v : vertices) box.extend(v);
  return box;
}

double TriangleMesh::area() const {
  double a = 0;
  for (const auto& f : faces) {
    a += 0.5 * (vertices[f[1]] - vertices[f[0]]).cross(vertices[f[2]] - vertices[f[0]]).norm();
  }
  return a;
}

Eigen::Vector3d closestPointOnTriangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                       const Eigen::Vector3d& c) {
  const Eigen::Vector3d ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return a;
  const Eigen::Vector3d bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return b;
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) return a + d1 / (d1 - d3) * ab;
  const Eigen::Vector3d cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return c;
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) return a + d2 / (d2 - d6) * ac;
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) return b + (d4 - d3) / ((d4 - d3) + (d5 - d6)) * (c - b);
  const double denom = 1.0 / (va + vb + vc);
  return a + ab * (vb * denom) + ac * (vc * denom);
}

Eigen::Vector3d TriangleMesh::surfaceCentroid() const {
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  double total = 0;
  for (const auto& f : faces) {
    const Eigen::Vector3d a = vertices[f[0]].cast<double>(), b = vertices[f[1]].cast<double>(),
                          c = vertices[f[2]].cast<double>();
    const double w = 0.5 * (b - a).cross(c - a).norm();
    sum += w * (a + b + c) / 3.0;
    total += w;
  }
  return total > 0 ? Eigen::Vector3d(sum / total) : Eigen::Vector3d::Zero();
}

namespace {

std::string lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), ::tolower);
  return s;
}

TriangleMesh loadPly(const std::string& path, const std::string& data, double scale) {
  const ply::Body body = ply::readBody(path, data, ply::parse(path, data));
  const auto& props = body.vertex_props;
  const auto at = [&](const char* name) {
    return static_cast<size_t>(std::find(props.begin(), props.end(), name) - props.begin());
  };
  const size_t ix = at("x"), iy = at("y"), iz = at("z"), n = props.size();
  if (ix == n || iy == n || iz == n) throw ConfigError(path + ": PLY vertex element lacks x, y or z");
  TriangleMesh mesh;
  const size_t count = n ? body.vertices.size() / n : 0;
  mesh.vertices.reserve(count);
  for (size_t k = 0; k < count; ++k) {
    const double* v = &body.vertices[k * n];
    mesh.vertices.emplace_back(static_cast<float>(v[ix] * scale), static_cast<float>(v[iy] * scale),
                               static_cast<float>(v[iz] * scale));
  }
  for (const auto& list : body.faces) {
    for (size_t j = 2; j < list.size(); ++j)  // fan-triangulate polygons
      mesh.faces.emplace_back(static_cast<int>(list[0]), static_cast<int>(list[j - 1]), static_cast<int>(list[j]));
  }
  return mesh;
}

}  // namespace

TriangleMesh loadMesh(const std::string& path, double scale) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw ConfigError(path + ": cannot open mesh file (missing or unreadable)");
  std::string data((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const size_t dot = path.find_last_of("./");
  const std::string ext = dot != std::string::npos && path[dot] == '.' ? lower(path.substr(dot + 1)) : "";
  TriangleMesh mesh;
  if (ext == "ply" || data.rfind("ply", 0) == 0) {
    mesh = loadPly(path, data, scale);
  } else {
    // Only formats whose importer the extension names: given an unknown extension assimp guesses
    // the format from the content, and some of its importers trust counts in a file (a 45-byte
    // input made its Quick3D reader ask for 3.6 TB).
    static const char* const kFormats[] = {"stl", "obj", "off", "gltf", "glb", "3mf", "dae"};
    if (std::find(std::begin(kFormats), std::end(kFormats), ext) == std::end(kFormats)) {
      throw ConfigError(path + ": unsupported mesh format '" + ext +
                        "' (use .ply, .stl, .obj, .off, .gltf, .glb, .3mf or .dae)");
    }
    data.clear();
    mesh = loadMeshWithAssimp(path, scale);
  }
  for (const auto& v : mesh.vertices) {
    if (!v.allFinite()) throw ConfigError(path + ": mesh has a non-finite vertex coordinate");
  }
  const int nv = static_cast<int>(mesh.vertices.size());
  for (size_t i = 0; i < mesh.faces.size(); ++i) {
    const Eigen::Vector3i& f = mesh.faces[i];
    if ((f.array() < 0).any() || (f.array() >= nv).any())
      throw ConfigError(path + ": face " + std::to_string(i) + " refers to vertex " +
                        std::to_string((f.array() < 0).any() ? f.minCoeff() : f.maxCoeff()) + " of " + std::to_string(nv));
  }
  return mesh;
}

void saveMeshPly(const std::string& path, const TriangleMesh& mesh) {
  std::ostringstream out;
  out << "ply\nformat binary_little_endian 1.0\ncomment cellsight mesh, metres\n"
      << "element vertex " << mesh.vertices.size() << "\nproperty float x\nproperty float y\n"
      << "property float z\nelement face " << mesh.faces.size()
      << "\nproperty list uchar int vertex_indices\nend_header\n";
  for (const auto& v : mesh.vertices) out.write(reinterpret_cast<const char*>(v.data()), 12);
  for (const auto& f : mesh.faces) {
    const uint8_t n = 3;
    out.write(reinterpret_cast<const char*>(&n), 1);
    out.write(reinterpret_cast<const char*>(f.data()), 12);
  }
  writeFileAtomic(path, out.str());
}

std::string MeshCheck::describe() const {
  std::ostringstream s;
  s << degenerate_faces << " degenerate faces, " << bad_indices << " out-of-range indices, "
    << nonmanifold_edges << " non-manifold edges, " << boundary_edges << " boundary edges";
  return s.str();
}

MeshCheck checkMesh(const TriangleMesh& mesh, double min_area) {
  MeshCheck c;
  std::unordered_map<uint64_t, int> edges;
  const auto nv = static_cast<int>(mesh.vertices.size());
  for (const auto& f : mesh.faces) {
    if ((f.array() < 0).any() || (f.array() >= nv).any()) {
      ++c.bad_indices;
      continue;
    }
    const auto& a = mesh.vertices[f[0]];
    const auto& b = mesh.vertices[f[1]];
    const auto& d = mesh.vertices[f[2]];
    if (f[0] == f[1] || f[1] == f[2] || f[0] == f[2] ||
        0.5 * (b - a).cross(d - a).norm() < min_area) {
      ++c.degenerate_faces;
      continue;
    }
    for (int k = 0; k < 3; ++k) {
      uint64_t i = static_cast<uint32_t>(f[k]), j = static_cast<uint32_t>(f[(k + 1) % 3]);
      if (i > j) std::swap(i, j);
      ++edges[(i << 32) | j];
    }
  }
  for (const auto& e : edges) {
    if (e.second == 1) ++c.boundary_edges;
    if (e.second > 2) ++c.nonmanifold_edges;
  }
  return c;
}

PlanarFaces planarFaces(const TriangleMesh& mesh, double coplanar_angle, double crease_angle) {
  PlanarFaces out;
  const size_t nf = mesh.faces.size();
  out.group.assign(nf, -1);
  // weld vertices by position (meshes often repeat a corner per face)
  std::map<std::array<int64_t, 3>, int> weld;
  std::vector<int> vid(mesh.vertices.size());
  for (size_t i = 0; i < mesh.vertices.size(); ++i) {
    const Eigen::Vector3f& v = mesh.vertices[i];
    const std::array<int64_t, 3> key{std::llround(v.x() * 1e7), std::llround(v.y() * 1e7), std::llround(v.z() * 1e7)};
    vid[i] = weld.emplace(key, static_cast<int>(weld.size())).first->second;
  }
  std::vector<Eigen::Vector3d> normal(nf, Eigen::Vector3d::Zero());
  std::map<std::pair<int, int>, std::vector<int>> edges;
  auto edgeKey = [&](int a, int b) { return std::make_pair(std::min(vid[a], vid[b]), std::max(vid[a], vid[b])); };
  for (size_t f = 0; f < nf; ++f) {
    const auto& t = mesh.faces[f];
    const Eigen::Vector3d a = mesh.vertices[t[0]].cast<double>(), b = mesh.vertices[t[1]].cast<double>(),
                          c = mesh.vertices[t[2]].cast<double>();
    const Eigen::Vector3d n = (b - a).cross(c - a);
    if (!(n.norm() > 0)) continue;
    normal[f] = n.normalized();
    for (int k = 0; k < 3; ++k) edges[edgeKey(t[k], t[(k + 1) % 3])].push_back(static_cast<int>(f));
  }
  const double cos_coplanar = std::cos(coplanar_angle), cos_crease = std::cos(crease_angle);
  for (size_t seed = 0; seed < nf; ++seed) {
    if (out.group[seed] >= 0 || normal[seed].squaredNorm() == 0) continue;
    const int g = static_cast<int>(out.groups.size());
    out.groups.emplace_back();
    out.groups[g].normal = normal[seed];
    std::vector<int> stack{static_cast<int>(seed)};
    out.group[seed] = g;
    while (!stack.empty()) {
      const int f = stack.back();
      stack.pop_back();
      const auto& t = mesh.faces[f];
      for (int k = 0; k < 3; ++k) {
        for (int o : edges[edgeKey(t[k], t[(k + 1) % 3])]) {
          if (out.group[o] >= 0 || normal[o].dot(normal[seed]) < cos_coplanar) continue;
          out.group[o] = g;
          stack.push_back(o);
        }
      }
    }
  }
  // creases: a group's edges not shared within the group, whose other side turns sharply
  for (size_t f = 0; f < nf; ++f) {
    const int g = out.group[f];
    if (g < 0) continue;
    const auto& t = mesh.faces[f];
    for (int k = 0; k < 3; ++k) {
      const auto& adj = edges[edgeKey(t[k], t[(k + 1) % 3])];
      bool inside = false, soft = false;
      for (int o : adj) {
        if (o == static_cast<int>(f)) continue;
        if (out.group[o] == g) inside = true;
        else if (normal[o].dot(normal[f]) >= cos_crease) soft = true;
      }
      if (inside || soft) continue;
      out.groups[g].creases.emplace_back(mesh.vertices[t[k]].cast<double>(), mesh.vertices[t[(k + 1) % 3]].cast<double>());
    }
  }
  for (auto& g : out.groups) {
    for (const auto& [a, b] : g.creases) g.crease_bounds.emplace_back(0.5 * (a + b), 0.5 * (b - a).norm());
  }
  return out;
}

double PlanarFaces::creaseDistance(int face, const Eigen::Vector3d& p) const {
  double best = std::numeric_limits<double>::infinity();
  if (face < 0 || face >= static_cast<int>(group.size()) || group[face] < 0) return best;
  const Group& g = groups[group[face]];
  if (g.creases.empty()) return best;
  // p on the group's plane (every crease lies in it)
  const Eigen::Vector3d pp = p - g.normal * g.normal.dot(p - g.creases.front().first);
  for (size_t c = 0; c < g.creases.size(); ++c) {
    // no nearer than its midpoint's distance less half its length
    const double lower = (pp - g.crease_bounds[c].first).norm() - g.crease_bounds[c].second;
    if (lower >= best) continue;
    const auto& [a, b] = g.creases[c];
    const Eigen::Vector3d e = b - a;
    const Eigen::Vector3d w = pp - a;
    const double u = std::clamp(w.dot(e) / std::max(e.squaredNorm(), 1e-300), 0.0, 1.0);
    best = std::min(best, (w - u * e).norm());
  }
  return best;
}

double PlanarFaces::creaseExit(int face, const Eigen::Vector3d& p, const Eigen::Vector3d& d) const {
  double best = std::numeric_limits<double>::infinity();
  if (face < 0 || face >= static_cast<int>(group.size()) || group[face] < 0) return best;
  const Group& g = groups[group[face]];
  const Eigen::Vector3d& n = g.normal;
  for (const auto& [a, b] : g.creases) {
    // p + s·d = a + u·e in the plane: s = -((w×e)·n)/((d×e)·n), u = ((w×d)·n)/((e×d)·n)
    const Eigen::Vector3d e = b - a, w = p - a;
    const double den = d.cross(e).dot(n);
    if (std::abs(den) < 1e-300) continue;
    const double s = -w.cross(e).dot(n) / den;
    const double u = w.cross(d).dot(n) / -den;
    if (s >= 0 && u >= 0 && u <= 1) best = std::min(best, s);
  }
  return best;
}

TriangleMesh loadValidMesh(const std::string& path, double scale) {
  TriangleMesh mesh = loadMesh(path, scale);
  if (mesh.faces.empty()) throw ConfigError(path + ": mesh has no faces");
  const MeshCheck c = checkMesh(mesh);
  if (!c.ok()) throw ConfigError(path + ": invalid mesh: " + c.describe());
  return mesh;
}

TriangleMesh makeBox(const Eigen::Vector3d& size) {
  TriangleMesh m;
  const Eigen::Vector3d h = size / 2;
  for (int i = 0; i < 8; ++i) {
    m.vertices.emplace_back((i & 1 ? h.x() : -h.x()), (i & 2 ? h.y() : -h.y()),
                            (i & 4 ? h.z() : -h.z()));
  }
  const int quads[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4},
                           {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
  for (const auto& q : quads) {
    m.faces.emplace_back(q[0], q[1], q[2]);
    m.faces.emplace_back(q[0], q[2], q[3]);
  }
  return m;
}

TriangleMesh makeTube(double ro, double ri, double height, int segments) {
  TriangleMesh m;
  for (int i = 0; i < segments; ++i) {
    const double a = 2 * M_PI * i / segments;
    const float c = static_cast<float>(std::cos(a)), s = static_cast<float>(std::sin(a));
    m.vertices.emplace_back(ro * c, ro * s, 0);
    m.vertices.emplace_back(ro * c, ro * s, height);
    m.vertices.emplace_back(ri * c, ri * s, 0);
    m.vertices.emplace_back(ri * c, ri * s, height);
  }
  for (int i = 0; i < segments; ++i) {
    const int a = 4 * i, b = 4 * ((i + 1) % segments);
    m.faces.emplace_back(a + 0, b + 0, b + 1);  // outer wall
    m.faces.emplace_back(a + 0, b + 1, a + 1);
    m.faces.emplace_back(a + 2, b + 3, b + 2);  // inner wall (facing the axis)
    m.faces.emplace_back(a + 2, a + 3, b + 3);
    m.faces.emplace_back(a + 1, b + 1, b + 3);  // top ring
    m.faces.emplace_back(a + 1, b + 3, a + 3);
    m.faces.emplace_back(a + 0, b + 2, b + 0);  // bottom ring
    m.faces.emplace_back(a + 0, a + 2, b + 2);
  }
  return m;
}

TriangleMesh makeCylinder(double radius, double height, int segments) {
  std::vector<Eigen::Vector2d> poly;
  for (int i = 0; i < segments; ++i) {
    const double a = 2 * M_PI * i / segments;
    poly.emplace_back(radius * std::cos(a), radius * std::sin(a));
  }
  return makeExtrusion(poly, height);
}

TriangleMesh makeSphere(double radius, int subdivisions) {
  const double t = (1.0 + std::sqrt(5.0)) / 2.0;
  std::vector<Eigen::Vector3d> v = {{-1, t, 0}, {1, t, 0}, {-1, -t, 0}, {1, -t, 0},
                                    {0, -1, t}, {0, 1, t}, {0, -1, -t}, {0, 1, -t},
                                    {t, 0, -1}, {t, 0, 1}, {-t, 0, -1}, {-t, 0, 1}};
  std::vector<Eigen::Vector3i> f = {{0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11},
                                    {1, 5, 9},  {5, 11, 4}, {11, 10, 2}, {10, 7, 6}, {7, 1, 8},
                                    {3, 9, 4},  {3, 4, 2},  {3, 2, 6},   {3, 6, 8},  {3, 8, 9},
                                    {4, 9, 5},  {2, 4, 11}, {6, 2, 10},  {8, 6, 7},  {9, 8, 1}};
  for (auto& p : v) p.normalize();
  for (int s = 0; s < subdivisions; ++s) {
    std::map<std::pair<int, int>, int> mid;
    auto midpoint = [&](int a, int b) {
      auto key = std::minmax(a, b);
      auto it = mid.find(key);
      if (it != mid.end()) return it->second;
      v.push_back((v[a] + v[b]).normalized());
      return mid[key] = static_cast<int>(v.size()) - 1;
    };
    std::vector<Eigen::Vector3i> nf;
    for (const auto& tri : f) {
      const int a = midpoint(tri[0], tri[1]), b = midpoint(tri[1], tri[2]),
                c = midpoint(tri[2], tri[0]);
      nf.emplace_back(tri[0], a, c);
      nf.emplace_back(tri[1], b, a);
      nf.emplace_back(tri[2], c, b);
      nf.emplace_back(a, b, c);
    }
    f.swap(nf);
  }
  TriangleMesh m;
  for (const auto& p : v) m.vertices.push_back((p * radius).cast<float>());
  m.faces = f;
  return m;
}

TriangleMesh makeExtrusion(const std::vector<Eigen::Vector2d>& poly, double height) {
  // Ear-clipping triangulation of a simple counter-clockwise polygon for the caps.
  const int n = static_cast<int>(poly.size());
  std::vector<Eigen::Vector3i> cap;
  std::vector<int> idx(n);
  for (int i = 0; i < n; ++i) idx[i] = i;
  auto cross = [](const Eigen::Vector2d& a, const Eigen::Vector2d& b, const Eigen::Vector2d& c) {
    return (b - a).x() * (c - a).y() - (b - a).y() * (c - a).x();
  };
  int guard = 0;
  while (idx.size() > 3 && guard++ < 10 * n * n) {
    bool clipped = false;
    for (size_t i = 0; i < idx.size(); ++i) {
      const int a = idx[(i + idx.size() - 1) % idx.size()], b = idx[i],
                c = idx[(i + 1) % idx.size()];
      if (cross(poly[a], poly[b], poly[c]) <= 1e-15) continue;
      bool inside = false;
      for (int j : idx) {
        if (j == a || j == b || j == c) continue;
        if (cross(poly[a], poly[b], poly[j]) >= 0 && cross(poly[b], poly[c], poly[j]) >= 0 &&
            cross(poly[c], poly[a], poly[j]) >= 0) {
          inside = true;
          break;
        }
      }
      if (inside) continue;
      cap.emplace_back(a, b, c);
      idx.erase(idx.begin() + static_cast<long>(i));
      clipped = true;
      break;
    }
    if (!clipped) break;
  }
  if (idx.size() == 3) cap.emplace_back(idx[0], idx[1], idx[2]);
  TriangleMesh m;
  for (const auto& p : poly) m.vertices.emplace_back(p.x(), p.y(), 0);
  for (const auto& p : poly) m.vertices.emplace_back(p.x(), p.y(), height);
  for (const auto& t : cap) {
    m.faces.emplace_back(t[0], t[2], t[1]);              // bottom, facing -z
    m.faces.emplace_back(t[0] + n, t[1] + n, t[2] + n);  // top, facing +z
  }
  for (int i = 0; i < n; ++i) {
    const int j = (i + 1) % n;
    m.faces.emplace_back(i, j, j + n);
    m.faces.emplace_back(i, j + n, i + n);
  }
  return m;
}

}  // namespace cellsight
