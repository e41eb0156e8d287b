// The part model library (issue 4, item 2): config/models/<id>/ meshes + metadata, model clouds
// sampled from the meshes at the scan's resolution with outward normals, and FPFH descriptors,
// each computed once per (model, resolution) and cached in memory.
#pragma once
#include <array>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "cellsight/common/scan_cloud.hpp"
#include "cellsight/common/mesh.hpp"
#include "cellsight/common/model_info.hpp"

namespace cellsight {

using Fpfh = std::array<float, 33>;

/// How sampleMesh keeps one point per cell.
enum class CellSample {
  kSurfacePoint,  ///< the sample nearest the cell centre: on the surface, its face's normal (models)
  kCentroid,      ///< the cell's centroid and mean normal, as a voxel-grid filter of a scan gives
};

/// Area-weighted random samples on the mesh (seeded), thinned to one per `spacing` voxel;
/// normals are the outward face normals.
ScanCloud sampleMesh(const TriangleMesh& mesh, double spacing, uint64_t seed = 1,
                     CellSample keep = CellSample::kSurfacePoint);

/// FPFH (PCL) for every point of a cloud with normals, support radius in metres.
std::vector<Fpfh> computeFpfh(const ScanCloud& cloud_with_normals, double radius);

struct ModelEntry {
  ModelInfo info;
  TriangleMesh mesh;         ///< empty for a model given as a point cloud
  ScanCloud source_cloud;    ///< the reference cloud of a cloud model (thesis: "CAD mesh or reference cloud")
  Eigen::Vector3f sensor = Eigen::Vector3f::Zero();  ///< where the reference cloud was seen from
  Eigen::AlignedBox3f bounds;
  std::vector<std::string> warnings;  ///< e.g. degenerate (flat) geometry
};

class ModelLibrary {
 public:
  /// Loads every `<folder>/<id>/model.yaml`; a missing or corrupt model throws ConfigError
  /// naming the file. A flat or tiny model is kept with a warning.
  explicit ModelLibrary(const std::string& folder);
  /// An empty library, filled with addCloudModel().
  ModelLibrary() = default;

  /// Adds a model given as a reference point cloud (e.g. an earlier scan of the part), seen from
  /// `sensor` (model frame; orients the normals). Throws std::invalid_argument for fewer than
  /// 10 finite points or an id already present.
  void addCloudModel(const std::string& id, const ScanCloud& cloud, const Eigen::Vector3f& sensor);
  /// Adds a model given as a mesh (model frame = mesh frame). Throws std::invalid_argument for
  /// an empty mesh or an id already present.
  void addMeshModel(const std::string& id, const TriangleMesh& mesh);

  std::vector<std::string> ids() const;
  bool has(const std::string& id) const { return models_.count(id) > 0; }
  /// Throws std::out_of_range naming the id and the known ids.
  const ModelEntry& model(const std::string& id) const;
  /// The model cloud at a resolution (cached).
  std::shared_ptr<const ScanCloud> cloud(const std::string& id, double resolution) const;
  /// FPFH of that cloud at a support radius (cached).
  std::shared_ptr<const std::vector<Fpfh>> descriptors(const std::string& id, double resolution, double radius) const;

 private:
  std::map<std::string, ModelEntry> models_;
  mutable std::mutex mutex_;
  mutable std::map<std::pair<std::string, long>, std::shared_ptr<const ScanCloud>> clouds_;
  mutable std::map<std::tuple<std::string, long, long>, std::shared_ptr<const std::vector<Fpfh>>> fpfh_;
};

}  // namespace cellsight
