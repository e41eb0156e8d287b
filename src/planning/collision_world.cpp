#include "cellsight/planning/collision_world.hpp"

#include <fcl/geometry/bvh/BVH_model.h>
#include <fcl/geometry/octree/octree.h>
#include <fcl/geometry/shape/box.h>
#include <fcl/geometry/shape/cylinder.h>
#include <fcl/geometry/shape/sphere.h>
#include <fcl/narrowphase/collision.h>
#include <fcl/narrowphase/collision_object.h>
#include <fcl/narrowphase/distance.h>
#include <octomap/OcTree.h>

#include <cmath>
#include <limits>
#include <map>
#include <mutex>
#include <stdexcept>
#include <unordered_map>

#include "cellsight/common/raycaster.hpp"

namespace cellsight {

namespace {

using Bvh = fcl::BVHModel<fcl::OBBRSSd>;

std::shared_ptr<Bvh> bvhOf(const TriangleMesh& mesh) {
  auto m = std::make_shared<Bvh>();
  std::vector<fcl::Vector3d> pts;
  pts.reserve(mesh.vertices.size());
  for (const auto& v : mesh.vertices) pts.emplace_back(v.cast<double>());
  std::vector<fcl::Triangle> tris;
  tris.reserve(mesh.faces.size());
  for (const auto& f : mesh.faces) tris.emplace_back(f[0], f[1], f[2]);
  m->beginModel();
  m->addSubModel(pts, tris);
  m->endModel();
  m->computeLocalAABB();
  return m;
}

bool overlap(const fcl::AABBd& a, const fcl::AABBd& b) { return a.overlap(b); }

}  // namespace

/// BVHs per mesh, shared by a world and its copies (built once per part model).
struct BvhCache {
  std::mutex mutex;
  std::map<const TriangleMesh*, std::pair<std::shared_ptr<const TriangleMesh>, std::shared_ptr<Bvh>>> bvh;
  std::shared_ptr<Bvh> get(const std::shared_ptr<const TriangleMesh>& mesh) {
    std::lock_guard<std::mutex> lock(mutex);
    auto& e = bvh[mesh.get()];
    if (!e.second) e = {mesh, bvhOf(*mesh)};
    return e.second;
  }
};

struct CollisionWorld::Impl {
  std::shared_ptr<BvhCache> cache = std::make_shared<BvhCache>();
  struct Object {
    std::string name;
    std::shared_ptr<const TriangleMesh> mesh;
    std::shared_ptr<Bvh> bvh;
    std::shared_ptr<fcl::CollisionObjectd> obj;
    Eigen::Isometry3d pose;
  };
  std::map<int, Object> objects;
  int next_id = 0;
  std::shared_ptr<octomap::OcTree> octree;
  std::shared_ptr<fcl::OcTreed> octree_geom;
  std::shared_ptr<fcl::CollisionObjectd> octree_obj;
  size_t voxels = 0;
  std::shared_ptr<fcl::CollisionObjectd> table, table_low;
  // per-arm-shape geometry, built lazily for the arm it is first used with
  mutable std::vector<std::shared_ptr<fcl::CollisionObjectd>> shape_objs;
  mutable const ArmModel* shapes_of = nullptr;
  // the carried part's padded box, per mesh (the mesh is kept alive with it)
  mutable std::map<const TriangleMesh*, std::pair<std::shared_ptr<const TriangleMesh>, std::shared_ptr<fcl::Boxd>>> carried_box;
};

CollisionWorld::CollisionWorld(const CollisionWorldConfig& config, double table_z, const Eigen::Vector2d& table_center,
                               const Eigen::Vector2d& table_size)
    : config_(config), impl_(std::make_unique<Impl>()) {
  if (!(config_.octree_resolution > 0) || !(table_size.x() > 0 && table_size.y() > 0) || !std::isfinite(table_z)) {
    throw std::invalid_argument("collision world: octree_resolution and the table size must be > 0, table z finite");
  }
  const double thick = 0.05;
  auto make_table = [&](double top) {
    auto box = std::make_shared<fcl::Boxd>(table_size.x(), table_size.y(), thick);
    fcl::Transform3d T = fcl::Transform3d::Identity();
    T.translation() = Eigen::Vector3d(table_center.x(), table_center.y(), top - thick / 2);
    auto o = std::make_shared<fcl::CollisionObjectd>(box, T);
    o->computeAABB();
    return o;
  };
  impl_->table = make_table(table_z);
  impl_->table_low = make_table(table_z - config_.contact_allowance);
}

CollisionWorld::~CollisionWorld() = default;

CollisionWorld::CollisionWorld(const CollisionWorld& o) : config_(o.config_), impl_(std::make_unique<Impl>()) {
  impl_->next_id = o.impl_->next_id;
  impl_->cache = o.impl_->cache;
  for (const auto& [id, ob] : o.impl_->objects) {
    Impl::Object c = ob;
    c.obj = std::make_shared<fcl::CollisionObjectd>(*ob.obj);  // a copy: the shared BVH is not recomputed
    impl_->objects[id] = c;
  }
  impl_->octree = o.impl_->octree;
  impl_->octree_geom = o.impl_->octree_geom;
  if (o.impl_->octree_obj) impl_->octree_obj = std::make_shared<fcl::CollisionObjectd>(*o.impl_->octree_obj);
  impl_->voxels = o.impl_->voxels;
  impl_->table = o.impl_->table;
  impl_->table_low = o.impl_->table_low;
}

int CollisionWorld::addObject(const std::string& name, std::shared_ptr<const TriangleMesh> mesh,
                              const Eigen::Isometry3d& pose) {
  if (!mesh || mesh->faces.empty()) throw std::invalid_argument("collision world: object '" + name + "' has an empty mesh");
  if (!pose.matrix().allFinite()) throw std::invalid_argument("collision world: object '" + name + "' has a non-finite pose");
  Impl::Object o;
  o.name = name;
  o.mesh = mesh;
  // one BVH per mesh, shared between instances (and copies of the world): FCL computes a
  // geometry's local box when an object is made of it, so a shared BVH gets its objects by copy
  o.pose = pose;
  for (const auto& [id, other] : impl_->objects) {
    if (other.mesh != mesh) continue;
    o.bvh = other.bvh;
    o.obj = std::make_shared<fcl::CollisionObjectd>(*other.obj);
    o.obj->setTransform(pose);
    o.obj->computeAABB();
    break;
  }
  if (!o.bvh) {
    // a BVH already built for this mesh (by this world or the one it was copied from) is shared;
    // FCL's object constructor recomputes its local box, which holds the same values
    o.bvh = impl_->cache->get(mesh);
    o.obj = std::make_shared<fcl::CollisionObjectd>(o.bvh, pose);
    o.obj->computeAABB();
  }
  const int id = impl_->next_id++;
  impl_->objects[id] = o;
  return id;
}

void CollisionWorld::removeObject(int id) { impl_->objects.erase(id); }

bool CollisionWorld::hasObject(int id) const { return impl_->objects.count(id) > 0; }

void CollisionWorld::moveObject(int id, const Eigen::Isometry3d& pose) {
  auto it = impl_->objects.find(id);
  if (it == impl_->objects.end()) throw std::out_of_range("collision world: no object " + std::to_string(id));
  it->second.pose = pose;
  it->second.obj->setTransform(pose);
  it->second.obj->computeAABB();
}

size_t CollisionWorld::setScan(const std::vector<Eigen::Vector3f>& points) {
  const double table_top = impl_->table->getTranslation().z() + 0.025;
  // points the located parts explain are left out: the parts are there as meshes
  RayCaster caster;
  bool any_object = false;
  for (const auto& [id, o] : impl_->objects) {
    caster.addMesh(*o.mesh, o.pose);
    any_object = true;
  }
  caster.commit();
  auto octree = std::make_shared<octomap::OcTree>(config_.octree_resolution);
  std::unordered_map<octomap::OcTreeKey, int, octomap::OcTreeKey::KeyHash> counts;
  for (const Eigen::Vector3f& p : points) {
    if (!p.allFinite() || p.z() < table_top + config_.table_margin) continue;
    if (any_object && caster.closestPoint(p, static_cast<float>(config_.explained_margin)).found) continue;
    octomap::OcTreeKey key;
    if (!octree->coordToKeyChecked(octomap::point3d(p.x(), p.y(), p.z()), key)) continue;
    ++counts[key];
  }
  size_t n = 0;
  for (const auto& [key, c] : counts) {
    if (c < config_.min_voxel_points) continue;
    octree->updateNode(key, true, true);
    ++n;
  }
  octree->updateInnerOccupancy();
  impl_->voxels = n;
  impl_->octree = octree;
  impl_->octree_obj.reset();
  impl_->octree_geom.reset();
  if (n > 0) {
    impl_->octree_geom = std::make_shared<fcl::OcTreed>(std::static_pointer_cast<const octomap::OcTree>(octree));
    impl_->octree_obj = std::make_shared<fcl::CollisionObjectd>(impl_->octree_geom, fcl::Transform3d::Identity());
    impl_->octree_obj->computeAABB();
  }
  return n;
}

void CollisionWorld::setPadding(double padding) {
  if (!(padding >= 0)) throw std::invalid_argument("collision world: padding must be >= 0");
  config_.padding = padding;
  impl_->shape_objs.clear();
  impl_->shapes_of = nullptr;
  impl_->carried_box.clear();
}

size_t CollisionWorld::occupiedVoxels() const { return impl_->voxels; }

std::vector<Eigen::Vector3d> CollisionWorld::voxelCentres() const {
  std::vector<Eigen::Vector3d> out;
  if (!impl_->octree) return out;
  for (auto it = impl_->octree->begin_leafs(); it != impl_->octree->end_leafs(); ++it) {
    if (impl_->octree->isNodeOccupied(*it)) out.emplace_back(it.getX(), it.getY(), it.getZ());
  }
  return out;
}

CollisionReport CollisionWorld::check(const ArmModel& arm, const JointVector& q, double opening,
                                      const CarriedPart* carried, int ignore_object) const {
  const auto& shapes = arm.shapes();
  if (impl_->shapes_of != &arm || impl_->shape_objs.size() != shapes.size()) {
    impl_->shape_objs.clear();
    const double p = config_.padding;
    for (const CollisionShape& s : shapes) {
      std::shared_ptr<fcl::CollisionGeometryd> g;
      switch (s.type) {
        case CollisionShape::Type::kBox:
          g = std::make_shared<fcl::Boxd>(s.size.x() + 2 * p, s.size.y() + 2 * p, s.size.z() + 2 * p);
          break;
        case CollisionShape::Type::kCylinder:
          g = std::make_shared<fcl::Cylinderd>(s.size.x() + p, s.size.y() + 2 * p);
          break;
        case CollisionShape::Type::kSphere:
          g = std::make_shared<fcl::Sphered>(s.size.x() + p);
          break;
      }
      impl_->shape_objs.push_back(std::make_shared<fcl::CollisionObjectd>(g, fcl::Transform3d::Identity()));
    }
    impl_->shapes_of = &arm;
  }
  const Isometries poses = arm.shapePoses(q, opening);
  for (size_t i = 0; i < shapes.size(); ++i) {
    impl_->shape_objs[i]->setTransform(poses[i]);
    impl_->shape_objs[i]->computeAABB();
  }
  fcl::CollisionRequestd req;
  CollisionReport r;
  double gap = std::numeric_limits<double>::infinity();
  // `weight` 0.5 for two moving shapes (their relative travel is at most twice one's bound);
  // `primitive`: both are boxes or cylinders, whose exact distance (GJK) is cheap
  fcl::DistanceRequestd dreq;
  auto collide = [&](const fcl::CollisionObjectd& a, const fcl::CollisionObjectd& b, double weight = 1.0,
                     bool primitive = false) {
    if (!overlap(a.getAABB(), b.getAABB())) {
      double d = a.getAABB().distance(b.getAABB());
      if (primitive && weight * d < 0.05 && weight * d < gap) {
        // a loose box of a turned link: the exact distance, when it could set the step
        fcl::DistanceResultd dres;
        fcl::distance(&a, &b, dreq, dres);
        d = std::max(d, dres.min_distance);
      }
      gap = std::min(gap, weight * d);
      return false;
    }
    fcl::CollisionResultd res;
    fcl::collide(&a, &b, req, res);
    if (res.isCollision()) return true;
    if (primitive) {
      fcl::DistanceResultd dres;
      fcl::distance(&a, &b, dreq, dres);
      gap = std::min(gap, weight * std::max(0.0, dres.min_distance));
    } else {
      gap = 0;
    }
    return false;
  };
  auto hit = [&](const std::string& a, const std::string& b) {
    r.collides = true;
    r.first = a;
    r.second = b;
    return r;
  };
  auto against_world = [&](const fcl::CollisionObjectd& o, const std::string& name, bool table, bool low_table,
                            int ignore) -> bool {
    if (table && collide(o, low_table ? *impl_->table_low : *impl_->table, 1.0, true)) return hit(name, "table"), true;
    if (impl_->octree_obj && collide(o, *impl_->octree_obj)) return hit(name, "scan voxels"), true;
    for (const auto& [id, ob] : impl_->objects) {
      if (id == ignore) continue;
      if (collide(o, *ob.obj)) return hit(name, "object " + ob.name), true;
    }
    return false;
  };
  for (size_t i = 0; i < shapes.size(); ++i) {
    // the base and the column stand beside the table
    if (against_world(*impl_->shape_objs[i], shapes[i].link, shapes[i].chain_index >= 2, false, -1)) return r;
  }
  // the tool against the base, the column and the upper arm
  for (size_t i = 0; i < shapes.size(); ++i) {
    if (shapes[i].chain_index < 6) continue;
    for (size_t k = 0; k < shapes.size(); ++k) {
      if (shapes[k].chain_index > 2) continue;
      if (collide(*impl_->shape_objs[i], *impl_->shape_objs[k], 0.5, true)) return hit(shapes[i].link, shapes[k].link);
    }
  }
  if (carried && carried->mesh) {
    // the carried part as its padded bounding box in its own frame: every checked shape is
    // padded, so the certified stepping covers the bare geometry between the steps
    auto& entry = impl_->carried_box[carried->mesh.get()];
    if (!entry.second) {
      const Eigen::AlignedBox3f b = carried->mesh->bounds();
      const Eigen::Vector3d size = (b.max() - b.min()).cast<double>() + Eigen::Vector3d::Constant(2 * config_.padding);
      entry = {carried->mesh, std::make_shared<fcl::Boxd>(size.x(), size.y(), size.z())};
    }
    const Eigen::Vector3d centre = carried->mesh->bounds().center().cast<double>();
    const Eigen::Isometry3d T = arm.fk(q) * arm.toolTcp() * carried->T_tcp_part * Eigen::Translation3d(centre);
    fcl::CollisionObjectd part(entry.second, T);
    part.computeAABB();
    const std::string name = "carried " + (carried->name.empty() ? std::string("part") : carried->name);
    if (against_world(part, name, true, true, ignore_object)) return r;
    for (size_t k = 0; k < shapes.size(); ++k) {
      if (shapes[k].chain_index > 4) continue;  // the wrist and the tool hold it
      if (collide(part, *impl_->shape_objs[k], 0.5, true)) return hit(name, shapes[k].link);
    }
  }
  r.clearance = std::isfinite(gap) ? gap : 1.0;
  return r;
}

}  // namespace cellsight
