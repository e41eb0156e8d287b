// Mesh files through assimp (Debian's libassimp): OBJ, glTF/GLB, OFF, 3MF, Collada, PLY, … The only
// translation unit that includes assimp. Files are imported without assimp's post-processing
// (Debian's build asserts, and aborts the process, on some malformed meshes there): every face
// index is checked here, polygons are split into triangle fans, node transforms are applied by
// walking the node tree, and vertices with identical coordinates are joined.
#include <assimp/Importer.hpp>
#include <assimp/scene.h>

#include <functional>
#include <map>
#include <tuple>

#include "cellsight/common/errors.hpp"
#include "cellsight/common/mesh.hpp"

namespace cellsight {

TriangleMesh loadMeshWithAssimp(const std::string& path, double scale) {
  Assimp::Importer importer;
  const aiScene* scene = importer.ReadFile(path, 0);
  if (!scene || !scene->mRootNode || (scene->mFlags & AI_SCENE_FLAGS_INCOMPLETE)) {
    const char* why = importer.GetErrorString();
    throw ConfigError(path + ": cannot read the mesh (assimp: " + std::string(why && *why ? why : "no mesh found") + ")");
  }
  TriangleMesh mesh;
  std::map<std::tuple<float, float, float>, int> index;  // identical coordinates → one vertex
  auto vertex = [&](const aiVector3D& p) {
    const Eigen::Vector3f v(static_cast<float>(p.x * scale), static_cast<float>(p.y * scale),
                            static_cast<float>(p.z * scale));
    if (!v.allFinite()) throw ConfigError(path + ": mesh has a non-finite vertex coordinate");
    const auto it = index.emplace(std::make_tuple(v.x(), v.y(), v.z()), static_cast<int>(mesh.vertices.size()));
    if (it.second) mesh.vertices.push_back(v);
    return it.first->second;
  };
  std::function<void(const aiNode*, const aiMatrix4x4&, int)> walk = [&](const aiNode* node, const aiMatrix4x4& parent,
                                                                          int depth) {
    if (depth > 64) throw ConfigError(path + ": node tree deeper than 64 levels");
    const aiMatrix4x4 T = parent * node->mTransformation;
    for (unsigned i = 0; i < node->mNumMeshes; ++i) {
      if (node->mMeshes[i] >= scene->mNumMeshes || !scene->mMeshes[node->mMeshes[i]])
        throw ConfigError(path + ": a node refers to a missing mesh");
      const aiMesh* am = scene->mMeshes[node->mMeshes[i]];
      if (am->mNumVertices > 0 && !am->mVertices) throw ConfigError(path + ": a mesh has no vertex array");
      for (unsigned f = 0; f < am->mNumFaces; ++f) {
        const aiFace& face = am->mFaces[f];
        if (face.mNumIndices < 3) continue;  // points and lines are not surfaces
        if (!face.mIndices) throw ConfigError(path + ": face " + std::to_string(f) + " has no indices");
        for (unsigned k = 0; k < face.mNumIndices; ++k) {
          if (face.mIndices[k] >= am->mNumVertices)
            throw ConfigError(path + ": face " + std::to_string(f) + " refers to vertex " +
                              std::to_string(face.mIndices[k]) + " of " + std::to_string(am->mNumVertices));
        }
        const int a = vertex(T * am->mVertices[face.mIndices[0]]);
        for (unsigned k = 1; k + 1 < face.mNumIndices; ++k)  // a fan: exact for triangles and convex polygons
          mesh.faces.emplace_back(a, vertex(T * am->mVertices[face.mIndices[k]]),
                                  vertex(T * am->mVertices[face.mIndices[k + 1]]));
      }
    }
    for (unsigned c = 0; c < node->mNumChildren; ++c) walk(node->mChildren[c], T, depth + 1);
  };
  walk(scene->mRootNode, aiMatrix4x4(), 0);
  if (mesh.faces.empty()) throw ConfigError(path + ": the file holds no triangles");
  return mesh;
}

}  // namespace cellsight
