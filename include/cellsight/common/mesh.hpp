// Triangle meshes: PLY (ASCII / binary little-endian) input by an own reader, every other format
// (STL, OBJ, glTF, OFF, …) through assimp, binary PLY output, validation, and primitive builders
// used to make the shipped part models.
#pragma once
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <string>
#include <vector>

namespace cellsight {

struct TriangleMesh {
  std::vector<Eigen::Vector3f> vertices;  ///< metres, in the mesh's own frame
  std::vector<Eigen::Vector3i> faces;     ///< counter-clockwise seen from outside

  void append(const TriangleMesh& other, const Eigen::Isometry3d& T = Eigen::Isometry3d::Identity());
  void transform(const Eigen::Isometry3d& T);
  Eigen::AlignedBox3f bounds() const;
  double area() const;
  /// Area-weighted centroid of the surface (exact; zero for a mesh without area).
  Eigen::Vector3d surfaceCentroid() const;
};

/// Closest point of triangle (a, b, c) to p (Voronoi regions; Ericson, Real-Time Collision
/// Detection §5.1.5).
Eigen::Vector3d closestPointOnTriangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                       const Eigen::Vector3d& c);

/// Loads a mesh file. PLY goes through the own reader: Debian's assimp 5.2.5 misreads the face
/// lists of binary little-endian PLY (face 0 of every shipped model comes back with index
/// 16777216). Every other format goes through assimp (STL, OBJ, glTF/GLB, OFF, 3MF, DAE, …). `scale` multiplies every coordinate (e.g. 0.001 for meshes in millimetres).
/// Throws ConfigError naming the file.
TriangleMesh loadMesh(const std::string& path, double scale = 1.0);
/// Any format through assimp: polygons as triangle fans, node transforms applied, vertices with
/// identical coordinates joined; every index checked (ConfigError naming the file).
TriangleMesh loadMeshWithAssimp(const std::string& path, double scale = 1.0);


/// Writes a binary little-endian PLY atomically.
void saveMeshPly(const std::string& path, const TriangleMesh& mesh);

struct MeshCheck {
  size_t degenerate_faces = 0;     ///< zero area or repeated vertex index
  size_t bad_indices = 0;          ///< index out of range
  size_t boundary_edges = 0;       ///< edges used by one face (holes)
  size_t nonmanifold_edges = 0;    ///< edges used by more than two faces
  bool ok() const { return degenerate_faces == 0 && bad_indices == 0 && nonmanifold_edges == 0; }
  std::string describe() const;
};

/// Checks topology; `min_area` in m² counts faces below it as degenerate.
MeshCheck checkMesh(const TriangleMesh& mesh, double min_area = 1e-14);

/// The mesh's flat faces and where they end. Triangles are grouped over shared edges (vertices
/// welded by position) while their normals stay within `coplanar_angle` of the group's first;
/// a group's boundary edges that meet a triangle turning by more than `crease_angle` (or no
/// triangle) are its creases: where a point sliding over the face leaves the surface. Edges to a
/// gently turning neighbour (the facets of a cylinder) are not creases.
struct PlanarFaces {
  struct Group {
    Eigen::Vector3d normal = Eigen::Vector3d::Zero();
    std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>> creases;
    std::vector<std::pair<Eigen::Vector3d, double>> crease_bounds;  ///< midpoint, half length
  };
  std::vector<int> group;  ///< per mesh face (-1: degenerate)
  std::vector<Group> groups;
  /// Nearest crease of p's group to p projected on the group's plane (infinity if none).
  double creaseDistance(int face, const Eigen::Vector3d& p) const;
  /// How far p (on or near `face`) moves along the in-plane direction d (any length; the
  /// answer is in units of d) before it crosses one of its group's creases; infinity if never.
  double creaseExit(int face, const Eigen::Vector3d& p, const Eigen::Vector3d& d) const;
};
PlanarFaces planarFaces(const TriangleMesh& mesh, double coplanar_angle = 1e-3, double crease_angle = 0.35);

/// Loads and validates: throws ConfigError if the file is unreadable, empty, has bad indices,
/// degenerate faces or non-manifold edges.
TriangleMesh loadValidMesh(const std::string& path, double scale = 1.0);

// ---- primitives (closed, outward-facing) ----
TriangleMesh makeBox(const Eigen::Vector3d& size);  ///< centred at the origin
/// Cylinder along z from z=0 to z=height; `segments` around.
TriangleMesh makeCylinder(double radius, double height, int segments = 48);
/// Tube (annulus) along z: outer and inner radius.
TriangleMesh makeTube(double outer_radius, double inner_radius, double height, int segments = 48);
/// Geodesic sphere centred at the origin.
TriangleMesh makeSphere(double radius, int subdivisions = 4);
/// Extrudes a simple counter-clockwise polygon (x, y) along z from 0 to height.
TriangleMesh makeExtrusion(const std::vector<Eigen::Vector2d>& polygon, double height);

}  // namespace cellsight
