#include "cellsight/common/raycaster.hpp"

#include <cmath>

#include <embree3/rtcore.h>

#include <stdexcept>
#include <string>
#include <vector>

namespace cellsight {

struct RayCaster::Impl {
  RTCDevice device = nullptr;
  RTCScene scene = nullptr;
  std::vector<std::vector<Eigen::Vector3f>> normals;  // per geometry, per triangle
  std::vector<std::vector<Eigen::Vector3f>> vertices;  // per geometry, world frame
  std::vector<std::vector<Eigen::Vector3i>> faces;     // per geometry
  bool committed = false;
};

namespace {
void embreeError(void*, RTCError code, const char* str) {
  throw std::runtime_error(std::string("Embree error ") + std::to_string(code) + ": " +
                           (str ? str : ""));
}
}  // namespace

RayCaster::RayCaster() : impl_(new Impl) {
  impl_->device = rtcNewDevice("threads=1");
  if (!impl_->device) throw std::runtime_error("Embree: cannot create a device");
  rtcSetDeviceErrorFunction(impl_->device, embreeError, nullptr);
  impl_->scene = rtcNewScene(impl_->device);
  rtcSetSceneBuildQuality(impl_->scene, RTC_BUILD_QUALITY_HIGH);
}

RayCaster::~RayCaster() {
  if (impl_->scene) rtcReleaseScene(impl_->scene);
  if (impl_->device) rtcReleaseDevice(impl_->device);
}

int RayCaster::addMesh(const TriangleMesh& mesh, const Eigen::Isometry3d& T) {
  if (impl_->committed) throw std::logic_error("RayCaster::addMesh after commit()");
  RTCGeometry geom = rtcNewGeometry(impl_->device, RTC_GEOMETRY_TYPE_TRIANGLE);
  auto* vb = static_cast<float*>(rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0,
                                                         RTC_FORMAT_FLOAT3, 3 * sizeof(float),
                                                         mesh.vertices.size()));
  const Eigen::Isometry3f Tf = T.cast<float>();
  std::vector<Eigen::Vector3f> world(mesh.vertices.size());
  for (size_t i = 0; i < mesh.vertices.size(); ++i) {
    world[i] = Tf * mesh.vertices[i];
    vb[3 * i + 0] = world[i].x();
    vb[3 * i + 1] = world[i].y();
    vb[3 * i + 2] = world[i].z();
  }
  auto* ib = static_cast<unsigned*>(rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0,
                                                            RTC_FORMAT_UINT3, 3 * sizeof(unsigned),
                                                            mesh.faces.size()));
  std::vector<Eigen::Vector3f> normals(mesh.faces.size());
  for (size_t i = 0; i < mesh.faces.size(); ++i) {
    const auto& f = mesh.faces[i];
    for (int k = 0; k < 3; ++k) ib[3 * i + k] = static_cast<unsigned>(f[k]);
    normals[i] = (world[f[1]] - world[f[0]]).cross(world[f[2]] - world[f[0]]).normalized();
  }
  rtcCommitGeometry(geom);
  const unsigned id = rtcAttachGeometry(impl_->scene, geom);
  rtcReleaseGeometry(geom);
  if (id != impl_->normals.size()) throw std::logic_error("RayCaster: unexpected geometry id");
  impl_->normals.push_back(std::move(normals));
  impl_->vertices.push_back(std::move(world));
  impl_->faces.push_back(mesh.faces);
  return static_cast<int>(id);
}

void RayCaster::commit() {
  rtcCommitScene(impl_->scene);
  impl_->committed = true;
}

namespace {
// Embree asserts on invalid rays (coordinates beyond ±1.8e18, NaN, negative t_near): such a
// ray, or an empty interval, hits nothing.
bool validRay(const Eigen::Vector3f& o, const Eigen::Vector3f& d, float t_near, float t_far) {
  const float big = 1e12f;
  return o.allFinite() && d.allFinite() && o.cwiseAbs().maxCoeff() < big && d.cwiseAbs().maxCoeff() < big &&
         t_near >= 0.f && t_far > t_near;
}
}  // namespace

RayHit RayCaster::intersect(const Eigen::Vector3f& o, const Eigen::Vector3f& d, float t_near,
                            float t_far) const {
  if (!validRay(o, d, t_near, t_far)) return RayHit();
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  RTCRayHit rh;
  rh.ray.org_x = o.x();
  rh.ray.org_y = o.y();
  rh.ray.org_z = o.z();
  rh.ray.dir_x = d.x();
  rh.ray.dir_y = d.y();
  rh.ray.dir_z = d.z();
  rh.ray.tnear = t_near;
  rh.ray.tfar = t_far;
  rh.ray.mask = 0xFFFFFFFF;
  rh.ray.flags = 0;
  rh.ray.time = 0;
  rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
  rtcIntersect1(impl_->scene, &ctx, &rh);
  RayHit out;
  if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return out;
  out.hit = true;
  out.t = rh.ray.tfar;
  out.geometry = static_cast<int>(rh.hit.geomID);
  out.triangle = static_cast<int>(rh.hit.primID);
  out.normal = impl_->normals[rh.hit.geomID][rh.hit.primID];
  return out;
}

bool RayCaster::occluded(const Eigen::Vector3f& o, const Eigen::Vector3f& d, float t_near,
                         float t_far) const {
  if (!validRay(o, d, t_near, t_far)) return false;
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  RTCRay ray;
  ray.org_x = o.x();
  ray.org_y = o.y();
  ray.org_z = o.z();
  ray.dir_x = d.x();
  ray.dir_y = d.y();
  ray.dir_z = d.z();
  ray.tnear = t_near;
  ray.tfar = t_far;
  ray.mask = 0xFFFFFFFF;
  ray.flags = 0;
  ray.time = 0;
  rtcOccluded1(impl_->scene, &ctx, &ray);
  return ray.tfar < 0;  // Embree sets tfar = -inf on a hit
}

ClosestPoint RayCaster::closestPoint(const Eigen::Vector3f& p, float max_distance) const {
  struct PointQueryState {
    const Impl* impl;
    Eigen::Vector3d p;
    ClosestPoint best;
  };
  PointQueryState st{impl_.get(), p.cast<double>(), ClosestPoint()};
  if (!p.allFinite() || !(max_distance > 0) || !impl_->committed) return st.best;
  RTCPointQuery q;
  q.x = p.x();
  q.y = p.y();
  q.z = p.z();
  q.time = 0.f;
  q.radius = max_distance;
  RTCPointQueryContext ctx;
  rtcInitPointQueryContext(&ctx);
  // called for every triangle whose bounds the (shrinking) query sphere touches
  auto visit = [](RTCPointQueryFunctionArguments* args) -> bool {
    auto* st = static_cast<PointQueryState*>(args->userPtr);
    const auto& f = st->impl->faces[args->geomID][args->primID];
    const auto& v = st->impl->vertices[args->geomID];
    const Eigen::Vector3d c =
        closestPointOnTriangle(st->p, v[f[0]].cast<double>(), v[f[1]].cast<double>(), v[f[2]].cast<double>());
    const float d = static_cast<float>((c - st->p).norm());
    if (d >= args->query->radius) return false;
    args->query->radius = d;
    st->best.found = true;
    st->best.point = c.cast<float>();
    st->best.distance = d;
    st->best.geometry = static_cast<int>(args->geomID);
    st->best.triangle = static_cast<int>(args->primID);
    st->best.normal = st->impl->normals[args->geomID][args->primID];
    return true;  // the radius shrank
  };
  rtcPointQuery(impl_->scene, &q, &ctx, visit, &st);
  return st.best;
}

}  // namespace cellsight
