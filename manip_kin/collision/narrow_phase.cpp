// The collision narrow phase in C++: coal's distance and witness points of the pairs a control
// cycle asks for, and each pair's damper features, in one call (manip_kin/collision/narrow_phase.py
// builds this with the system's C++ compiler and calls it through ctypes; its Python loop is the
// fallback and the reference the tests hold this to). mk_narrow_near places the robot's shapes on
// the model's frames and runs the broad phase of manip_kin/collision/distances.py
// (CollisionChecker._near_pairs, the reference) before it and the damper rows after it, on arrays
// that Python derives once per robot (mk_narrow_set_placement) and once per scene.
//
// Shapes are built as manip_kin/collision/geometry.py builds them: box (full extents), sphere,
// cylinder (radius, length along z), and a mesh file as its convex hull (coal's MeshLoader,
// then buildConvexHull(true, "Qt")). A C ABI only: no Python headers, no pybind.
#include <coal/BVH/BVH_model.h>
#include <coal/distance.h>
#include <coal/mesh_loader/loader.h>
#include <coal/shape/geometric_shapes.h>

#include <algorithm>
#include <cmath>
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

// The broad phase's arrays (set per scene) and state (carried between calls), as
// CollisionChecker._near_pairs keeps them: P pairs, dof joints.
struct BroadPhase {
  bool set = false;
  int dof = 0;
  double band = 0.0;
  std::vector<double> radius_sums;                // P
  std::vector<double> reach_pairs;                // dof x P
  std::vector<double> reach_most;                 // dof: each joint's largest reach over the pairs
  std::vector<double> moves_first, moves_second;  // P x dof: 1 where the joint moves the shape
  std::vector<double> centres;                    // shapes x 3: bounding-sphere centres
  std::vector<double> lower;                      // P: a lower bound on each pair's distance
  std::vector<double> previous, travel;           // dof; previous empty before the first call
  double budget = 0.0;
  std::vector<int> near_rows;
  bool has_cutoff = false;
  double near_cutoff = 0.0;
  std::vector<int> rows;       // scratch: the rows asked this call
  std::vector<double> lines;   // scratch: their columns
};

// Where the robot's shapes sit (set once per robot): each shape's model frame and its pose in
// that frame with its bounding-sphere centre as a fifth column, row-major 4 x 5.
struct Placement {
  bool set = false;
  int frame_count = 0;
  std::vector<int> shape_frames;
  std::vector<double> offsets;
  std::vector<double> placed;  // scratch: the shapes' [R | t | c] in base, robot_count x 3 x 5
};

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
  BroadPhase broad;
  Placement placement;
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

// placement.placed = frames[shape_frames] (the top 3 rows of each 4x4) times offsets, as
// CollisionChecker._place computes it.
void place_shapes(NarrowPhase* phase, const double* frames) {
  Placement& placement = phase->placement;
  for (int g = 0; g < phase->robot_count; ++g) {
    const double* frame = frames + 16 * placement.shape_frames[g];
    const double* offset = placement.offsets.data() + 20 * g;
    double* out = placement.placed.data() + 15 * g;
    for (int i = 0; i < 3; ++i)
      for (int c = 0; c < 5; ++c) {
        double sum = 0.0;
        for (int k = 0; k < 4; ++k) sum += frame[4 * i + k] * offset[5 * k + c];
        out[5 * i + c] = sum;
      }
  }
}

void compute_rows(NarrowPhase* phase, const double* placed, const int* rows, int row_count, double* out) {
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
}

// Into broad.rows: the pairs CollisionChecker._near_pairs would ask the narrow phase for at q
// (the same bounds, the same order of operations).
void select_rows(NarrowPhase* phase, const double* q, const double* placed, double cutoff) {
  BroadPhase& broad = phase->broad;
  const int dof = broad.dof, pairs = static_cast<int>(broad.radius_sums.size());
  if (!broad.previous.empty()) {
    for (int j = 0; j < dof; ++j) {
      const double step = std::abs(q[j] - broad.previous[j]);
      broad.travel[j] += step;
      broad.budget -= step * broad.reach_most[j];
    }
  }
  broad.previous.assign(q, q + dof);
  if (broad.has_cutoff && cutoff == broad.near_cutoff && broad.budget > 0.0) {
    broad.rows = broad.near_rows;
    return;
  }
  for (int k = 0; k < pairs; ++k) {
    double fall = 0.0;
    for (int j = 0; j < dof; ++j) fall += broad.travel[j] * broad.reach_pairs[j * pairs + k];
    broad.lower[k] -= fall;
  }
  std::fill(broad.travel.begin(), broad.travel.end(), 0.0);
  for (int g = 0; g < phase->robot_count; ++g)
    for (int i = 0; i < 3; ++i) broad.centres[3 * g + i] = placed[15 * g + 5 * i + 4];
  broad.rows.clear();
  for (int k = 0; k < pairs; ++k) {
    const double* a = broad.centres.data() + 3 * phase->first[k];
    const double* b = broad.centres.data() + 3 * phase->second[k];
    const double dx = a[0] - b[0], dy = a[1] - b[1], dz = a[2] - b[2];
    const double gap = std::sqrt(dx * dx + dy * dy + dz * dz) - broad.radius_sums[k];
    broad.lower[k] = std::max(broad.lower[k], gap);
    if (broad.lower[k] < cutoff + broad.band) broad.rows.push_back(k);
  }
  broad.near_rows = broad.rows;
  broad.has_cutoff = true;
  broad.near_cutoff = cutoff;
  broad.budget = broad.band;
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
    phase->broad.set = false;  // its arrays are per pair: mk_narrow_set_broad again
    return 0;
  } catch (const std::exception& error) {
    last_error = error.what();
    return -1;
  }
}

void mk_narrow_destroy(void* handle) { delete static_cast<NarrowPhase*>(handle); }

// Where the robot shapes sit: the model's frame_count frames (base first), each shape's frame
// index and its pose in that frame with its bounding-sphere centre as a fifth column (row-major
// robot_count x 4 x 5). Returns 0, or -1 (see mk_narrow_error).
int mk_narrow_set_placement(void* handle, int frame_count, const int* shape_frames, const double* offsets) {
  auto* phase = static_cast<NarrowPhase*>(handle);
  try {
    Placement placement;
    placement.frame_count = frame_count;
    placement.shape_frames.assign(shape_frames, shape_frames + phase->robot_count);
    for (int frame : placement.shape_frames)
      if (frame < 0 || frame >= frame_count)
        throw std::runtime_error("shape frame " + std::to_string(frame) + " not one of " +
                                 std::to_string(frame_count));
    placement.offsets.assign(offsets, offsets + 20 * phase->robot_count);
    placement.placed.assign(15 * phase->robot_count, 0.0);
    placement.set = true;
    phase->placement = std::move(placement);
    return 0;
  } catch (const std::exception& error) {
    last_error = error.what();
    return -1;
  }
}

// placed: the robot shapes' [R | t | c] in base, row-major (robot_count, 3, 5); rows: row_count pair
// indices; out: row_count x kRowWidth. Returns 0, or -1 (see mk_narrow_error).
int mk_narrow_compute(void* handle, const double* placed, const int* rows, int row_count, double* out) {
  try {
    compute_rows(static_cast<NarrowPhase*>(handle), placed, rows, row_count, out);
    return 0;
  } catch (const std::exception& error) {
    last_error = error.what();
    return -1;
  }
}

// The broad phase's arrays for the pairs of the last mk_narrow_set_scene (P of them), dof joints:
// radius_sums (P), reach_pairs (dof x P), reach_most (dof: each joint's largest reach over the
// pairs), moves_first and moves_second (P x dof), the obstacles' bounding-sphere centres (3
// each), and band [m]. Resets its state. Returns 0, or -1 (see
// mk_narrow_error) with no broad phase set.
int mk_narrow_set_broad(void* handle, int dof, double band, const double* radius_sums, const double* reach_pairs,
                        const double* reach_most, const double* moves_first, const double* moves_second,
                        const double* obstacle_centres) {
  auto* phase = static_cast<NarrowPhase*>(handle);
  try {
    BroadPhase broad;
    const int pairs = static_cast<int>(phase->first.size());
    const int obstacles = static_cast<int>(phase->shapes.size()) - phase->robot_count;
    broad.dof = dof;
    broad.band = band;
    broad.radius_sums.assign(radius_sums, radius_sums + pairs);
    broad.reach_pairs.assign(reach_pairs, reach_pairs + dof * pairs);
    broad.reach_most.assign(reach_most, reach_most + dof);
    broad.moves_first.assign(moves_first, moves_first + pairs * dof);
    broad.moves_second.assign(moves_second, moves_second + pairs * dof);
    broad.centres.assign(3 * (phase->robot_count + obstacles), 0.0);
    std::copy(obstacle_centres, obstacle_centres + 3 * obstacles, broad.centres.begin() + 3 * phase->robot_count);
    broad.lower.assign(pairs, -INFINITY);
    broad.travel.assign(dof, 0.0);
    broad.lines.assign(static_cast<size_t>(std::max(pairs, 1)) * kRowWidth, 0.0);
    broad.set = true;
    phase->broad = std::move(broad);
    return 0;
  } catch (const std::exception& error) {
    last_error = error.what();
    return -1;
  }
}

// One cycle of CollisionChecker._near_pairs: the robot shapes placed on frames (the model's
// frame_count 4x4 frames in base, row-major, then the joints' twists [w; v], row-major 6 x dof,
// as the generated frames function gives them), the broad phase at q (dof values), the narrow
// phase of the pairs it keeps, and of those nearer than cutoff: their rows (out_rows) and
// columns (out_columns, kRowWidth each). With damper ([d_i, d_s, gain]) also their damper rows
// (out_matrix, dof each) and bounds (out_bound); with travel (dof values, each joint's stopping
// travel) each distance is first lessened by what the pair closes over it, and only the pairs
// left within d_i are kept. counts: [pairs kept, pairs computed]. Returns 0, or -1 (see
// mk_narrow_error).
int mk_narrow_near(void* handle, const double* q, const double* frames, double cutoff, const double* damper,
                   const double* travel, int* out_rows, double* out_columns, double* out_matrix, double* out_bound,
                   int* counts) {
  auto* phase = static_cast<NarrowPhase*>(handle);
  try {
    BroadPhase& broad = phase->broad;
    if (!broad.set) throw std::runtime_error("no broad phase for this scene (mk_narrow_set_broad)");
    if (!phase->placement.set) throw std::runtime_error("no placement for the robot's shapes (mk_narrow_set_placement)");
    place_shapes(phase, frames);
    const double* placed = phase->placement.placed.data();
    select_rows(phase, q, placed, cutoff);
    const int asked = static_cast<int>(broad.rows.size());
    compute_rows(phase, placed, broad.rows.data(), asked, broad.lines.data());
    broad.near_rows.clear();
    int found = 0;
    const int dof = broad.dof;
    const double* twists = frames + 16 * phase->placement.frame_count;
    for (int r = 0; r < asked; ++r) {
      const int row = broad.rows[r];
      const double* line = broad.lines.data() + kRowWidth * r;
      const double distance = line[0];
      broad.lower[row] = distance;
      // Found at cutoff + what is left of the band or beyond: it cannot come within cutoff first.
      if (distance < cutoff + broad.budget) broad.near_rows.push_back(row);
      if (!(distance < cutoff)) continue;
      if (damper != nullptr) {
        const double* moves_first = broad.moves_first.data() + row * dof;
        const double* moves_second = broad.moves_second.data() + row * dof;
        double* matrix_row = out_matrix + dof * found;
        double closing = 0.0;
        for (int j = 0; j < dof; ++j) {
          double first = 0.0, second = 0.0;
          for (int i = 0; i < 6; ++i) {
            first += line[10 + i] * twists[i * dof + j];
            second += line[16 + i] * twists[i * dof + j];
          }
          matrix_row[j] = first * moves_first[j] - second * moves_second[j];
          if (travel != nullptr) closing += matrix_row[j] * travel[j];
        }
        const double left = distance - std::max(closing, 0.0);
        if (travel != nullptr && !(left < damper[0])) continue;
        out_bound[found] = damper[2] * (left - damper[1]) / (damper[0] - damper[1]);
      }
      out_rows[found] = row;
      std::copy(line, line + kRowWidth, out_columns + kRowWidth * found);
      ++found;
    }
    counts[0] = found;
    counts[1] = asked;
    return 0;
  } catch (const std::exception& error) {
    last_error = error.what();
    return -1;
  }
}

}  // extern "C"
