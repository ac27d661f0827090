// The collision narrow phase in C++: coal's distance and witness points of the pairs a control
// cycle asks for, and each pair's damper features, in one call (manip_kin/collision/narrow_phase.py
// builds this with the system's C++ compiler and calls it through ctypes; its Python loop is the
// fallback and the reference the tests hold this to).
//
// Shapes are built as manip_kin/collision/geometry.py builds them: box (full extents), sphere,
// cylinder (radius, length along z), and a mesh file as its convex hull (coal's MeshLoader,
// then buildConvexHull(true, "Qt")). A C ABI only: no Python headers, no pybind.
#include <coal/BVH/BVH_model.h>
#include <coal/distance.h>
#include <coal/mesh_loader/loader.h>
#include <coal/shape/geometric_shapes.h>

#include <algorithm>
#include <exception>
#include <map>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

namespace {

// One row of the output per asked pair: distance, point on first (3), point on second (3), unit
// normal first->second (3), then [p1 x n, n] and [p2 x n, n] (6 each).
constexpr int kRowWidth = 22;

std::string last_error;

struct NarrowPhase {
  std::vector<coal::CollisionGeometryPtr_t> shapes;  // robot shapes, then obstacles
  std::vector<coal::Transform3s> transforms;         // obstacles' stay as set; robot's set per call
  int robot_count = 0;
  std::vector<int> first, second;
  std::vector<std::unique_ptr<coal::ComputeDistance>> functors;
  coal::DistanceRequest request;
  coal::DistanceResult result;
  std::vector<char> placed;  // per robot shape: placed in this call yet
  std::map<std::string, coal::CollisionGeometryPtr_t> meshes;  // obstacle meshes by file and scale
};

coal::CollisionGeometryPtr_t make_shape(int kind, const double* size, const char* path) {
  switch (kind) {
    case 0:
      return std::make_shared<coal::Box>(size[0], size[1], size[2]);
    case 1:
      return std::make_shared<coal::Sphere>(size[0]);
    case 2:
      return std::make_shared<coal::Cylinder>(size[0], size[1]);
    case 3: {
      coal::MeshLoader loader;
      coal::BVHModelPtr_t mesh = loader.load(path, coal::Vec3s(size[0], size[1], size[2]));
      if (mesh->num_vertices < 4) throw std::runtime_error(std::string(path) + ": fewer than 4 vertices");
      mesh->buildConvexHull(true, "Qt");
      return mesh->convex;
    }
    default:
      throw std::runtime_error("unknown shape kind " + std::to_string(kind));
  }
}

void write_features(const coal::Vec3s& p, const coal::Vec3s& n, double* out) {
  out[0] = p[1] * n[2] - p[2] * n[1];
  out[1] = p[2] * n[0] - p[0] * n[2];
  out[2] = p[0] * n[1] - p[1] * n[0];
  out[3] = n[0];
  out[4] = n[1];
  out[5] = n[2];
}

}  // namespace

extern "C" {

const char* mk_narrow_error() { return last_error.c_str(); }

int mk_narrow_row_width() { return kRowWidth; }

// The robot's robot_count shapes: kinds, sizes (3 per shape) and paths (mesh files, "" otherwise).
// Returns a handle, or null (see mk_narrow_error). No pairs until mk_narrow_set_scene.
void* mk_narrow_create(int robot_count, const int* kinds, const double* sizes, const char** paths) {
  try {
    auto phase = std::make_unique<NarrowPhase>();
    phase->robot_count = robot_count;
    for (int i = 0; i < robot_count; ++i) {
      phase->shapes.push_back(make_shape(kinds[i], sizes + 3 * i, paths[i]));
      phase->transforms.emplace_back();
    }
    phase->placed.assign(robot_count, 0);
    return phase.release();
  } catch (const std::exception& error) {
    last_error = error.what();
    return nullptr;
  }
}

// The obstacles (as the robot's shapes, with their poses: 12 per obstacle, row-major 3x4 [R | t])
// and the pairs to be asked for: pair_count (first, second) shape indices, robot shapes first.
// Replaces the previous scene. A mesh obstacle is loaded once per (file, scale) per handle.
// Returns 0, or -1 (see mk_narrow_error) with the previous scene kept.
int mk_narrow_set_scene(void* handle, int obstacle_count, const int* kinds, const double* sizes, const char** paths,
                        const double* poses, int pair_count, const int* pairs) {
  auto* phase = static_cast<NarrowPhase*>(handle);
  try {
    std::vector<coal::CollisionGeometryPtr_t> shapes(phase->shapes.begin(), phase->shapes.begin() + phase->robot_count);
    std::vector<coal::Transform3s> transforms(phase->robot_count);
    for (int i = 0; i < obstacle_count; ++i) {
      const double* size = sizes + 3 * i;
      if (kinds[i] == 3) {
        std::string key = std::string(paths[i]) + "|" + std::to_string(size[0]) + "," + std::to_string(size[1]) +
                          "," + std::to_string(size[2]);
        auto known = phase->meshes.find(key);
        if (known == phase->meshes.end()) known = phase->meshes.emplace(key, make_shape(3, size, paths[i])).first;
        shapes.push_back(known->second);
      } else {
        shapes.push_back(make_shape(kinds[i], size, paths[i]));
      }
      const double* pose = poses + 12 * i;
      coal::Matrix3s rotation;
      rotation << pose[0], pose[1], pose[2], pose[4], pose[5], pose[6], pose[8], pose[9], pose[10];
      transforms.emplace_back();
      transforms.back().setTransform(rotation, coal::Vec3s(pose[3], pose[7], pose[11]));
    }
    const int count = static_cast<int>(shapes.size());
    std::vector<int> first, second;
    std::vector<std::unique_ptr<coal::ComputeDistance>> functors;
    for (int k = 0; k < pair_count; ++k) {
      int a = pairs[2 * k], b = pairs[2 * k + 1];
      if (a < 0 || b < 0 || a >= count || b >= count || a >= phase->robot_count)
        throw std::runtime_error("pair " + std::to_string(k) + " (" + std::to_string(a) + ", " + std::to_string(b) +
                                 "): not a robot shape and a shape of the " + std::to_string(count));
      first.push_back(a);
      second.push_back(b);
      functors.emplace_back(new coal::ComputeDistance(shapes[a].get(), shapes[b].get()));
    }
    phase->shapes.swap(shapes);
    phase->transforms.swap(transforms);
    phase->first.swap(first);
    phase->second.swap(second);
    phase->functors.swap(functors);
    return 0;
  } catch (const std::exception& error) {
    last_error = error.what();
    return -1;
  }
}

void mk_narrow_destroy(void* handle) { delete static_cast<NarrowPhase*>(handle); }

// placed: the robot shapes' [R | t | c] in base, row-major (robot_count, 3, 5); rows: row_count pair
// indices; out: row_count x kRowWidth. Returns 0, or -1 (see mk_narrow_error).
int mk_narrow_compute(void* handle, const double* placed, const int* rows, int row_count, double* out) {
  auto* phase = static_cast<NarrowPhase*>(handle);
  try {
    std::fill(phase->placed.begin(), phase->placed.end(), 0);
    for (int r = 0; r < row_count; ++r) {
      const int row = rows[r];
      if (row < 0 || row >= static_cast<int>(phase->functors.size())) throw std::runtime_error("row out of range");
      for (int shape : {phase->first[row], phase->second[row]}) {
        if (shape >= phase->robot_count || phase->placed[shape]) continue;
        const double* m = placed + 15 * shape;
        coal::Matrix3s rotation;
        rotation << m[0], m[1], m[2], m[5], m[6], m[7], m[10], m[11], m[12];
        phase->transforms[shape].setTransform(rotation, coal::Vec3s(m[3], m[8], m[13]));
        phase->placed[shape] = 1;
      }
      coal::DistanceResult& result = phase->result;
      result.clear();
      const double distance = (*phase->functors[row])(phase->transforms[phase->first[row]],
                                                       phase->transforms[phase->second[row]], phase->request, result);
      double* line = out + kRowWidth * r;
      line[0] = distance;
      const coal::Vec3s &p1 = result.nearest_points[0], &p2 = result.nearest_points[1], &n = result.normal;
      for (int i = 0; i < 3; ++i) {
        line[1 + i] = p1[i];
        line[4 + i] = p2[i];
        line[7 + i] = n[i];
      }
      write_features(p1, n, line + 10);
      write_features(p2, n, line + 16);
    }
    return 0;
  } catch (const std::exception& error) {
    last_error = error.what();
    return -1;
  }
}

}  // extern "C"
