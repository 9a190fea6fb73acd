#include "stereo_occupancy/sim/scene_images.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <random>
#include <vector>

namespace stereo_occupancy {

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
/// Pixels per side of the tiles whose rays share one list of boxes.
constexpr int kTilePx = 16;
/// A box with a corner nearer to the camera plane than this [m] may cover
/// any pixel (its corners' projections bound nothing): every tile tests it.
constexpr double kNearPlaneM = 1e-3;
/// The projected corners' rectangle grows by this much against rounding [px].
constexpr double kRectMarginPx = 1.0;

/// The tiles (inclusive ranges) whose pixels may see @p box; false if none.
bool boxTiles(const Eigen::AlignedBox3d& box, const Eigen::Isometry3d& T_C_W, const StereoCameraConfig& cfg,
              int tiles_x, int tiles_y, std::array<int, 4>* range) {
  double x0 = kInf, y0 = kInf, x1 = -kInf, y1 = -kInf;
  int behind = 0;  // corners at or behind the camera plane: a ray (z > 0 beyond the centre) cannot meet them
  bool near_plane = false;
  for (int c = 0; c < 8; ++c) {
    const Eigen::Vector3d p = T_C_W * box.corner(static_cast<Eigen::AlignedBox3d::CornerType>(c));
    if (p.z() <= 0.0) ++behind;
    if (p.z() <= kNearPlaneM) {
      near_plane = true;
      continue;
    }
    const double u = cfg.focal_length_px * p.x() / p.z() + cfg.cx_px,
                 v = cfg.focal_length_px * p.y() / p.z() + cfg.cy_px;
    x0 = std::min(x0, u), x1 = std::max(x1, u), y0 = std::min(y0, v), y1 = std::max(y1, v);
  }
  if (behind == 8) return false;  // the box lies wholly behind the camera
  if (near_plane) {
    *range = {0, 0, tiles_x - 1, tiles_y - 1};
    return true;
  }
  // A convex box in front of the camera projects inside its corners' hull.
  x0 -= kRectMarginPx, y0 -= kRectMarginPx, x1 += kRectMarginPx, y1 += kRectMarginPx;
  if (x1 < 0.0 || y1 < 0.0 || x0 > cfg.width_px - 1 || y0 > cfg.height_px - 1) return false;
  auto tile = [](double px, int tiles) { return std::clamp(static_cast<int>(std::floor(px / kTilePx)), 0, tiles - 1); };
  *range = {tile(x0, tiles_x), tile(y0, tiles_y), tile(x1, tiles_x), tile(y1, tiles_y)};
  return true;
}

/// A 32-bit integer hash (lowbias32): neighbouring inputs give unrelated outputs.
uint32_t hash32(uint32_t x) {
  x ^= x >> 16;
  x *= 0x7feb352du;
  x ^= x >> 15;
  x *= 0x846ca68bu;
  x ^= x >> 16;
  return x;
}

uint32_t hashCombine(uint32_t seed, uint32_t value) {
  return hash32(seed ^ (value + 0x9e3779b9u + (seed << 6) + (seed >> 2)));
}

/// @p h mapped to [0, 1).
double unitFromHash(uint32_t h) { return h * (1.0 / 4294967296.0); }

/// Value noise: hashed lattice values in [-1, 1] at the integer points,
/// interpolated with a smooth step; (u, v) in lattice units.
double valueNoise(double u, double v, uint32_t seed) {
  const double fu = std::floor(u), fv = std::floor(v);
  const int iu = static_cast<int>(fu), iv = static_cast<int>(fv);
  auto lattice = [&](int a, int b) {
    return 2.0 * unitFromHash(hashCombine(hashCombine(seed, static_cast<uint32_t>(a)), static_cast<uint32_t>(b))) - 1.0;
  };
  auto smooth = [](double t) { return t * t * (3.0 - 2.0 * t); };
  const double su = smooth(u - fu), sv = smooth(v - fv);
  const double bottom = lattice(iu, iv) + su * (lattice(iu + 1, iv) - lattice(iu, iv));
  const double top = lattice(iu, iv + 1) + su * (lattice(iu + 1, iv + 1) - lattice(iu, iv + 1));
  return bottom + sv * (top - bottom);
}

/// The standard deviation of valueNoise() (measured over 10^6 points): the
/// texture is scaled by it so that a contrast reads as a relative deviation.
constexpr double kValueNoiseStd = 0.43;
/// An octave counts fully at wavelengths from 3 footprints and fades out
/// linearly to nothing at 2 (the sampling limit of the pixels).
constexpr double kFullOctaveFootprints = 3.0;
constexpr double kNoOctaveFootprints = 2.0;
/// A face seen at grazing incidence is blurred as if seen at this cosine.
constexpr double kMinIncidenceCosine = 0.05;
/// At most this many texture samples along a pixel's stretched footprint.
constexpr int kMaxStretchSamples = 8;
constexpr uint32_t kGroundSurfaceId = 0xfffffff0u;

/// A surface point's face: its outward normal, its coordinates on the face
/// [m] and a number that tells the face from every other.
struct Face {
  Eigen::Vector3d W_normal;
  int axis;  ///< the normal's axis: u and v run along the next two, cyclically
  double u_m, v_m;
  uint32_t id;
};

Face faceAt(const SyntheticScene& scene, int object, const Eigen::Vector3d& W_point) {
  if (object < 0) return {Eigen::Vector3d::UnitZ(), 2, W_point.x(), W_point.y(), kGroundSurfaceId};
  const Eigen::AlignedBox3d& box = scene.boxes[static_cast<size_t>(object)];
  int axis = 0;
  bool at_max = false;
  double nearest = kInf;
  for (int a = 0; a < 3; ++a) {  // the face the point lies on: the nearest of the six planes
    const double to_min = std::abs(W_point[a] - box.min()[a]), to_max = std::abs(W_point[a] - box.max()[a]);
    if (to_min < nearest) nearest = to_min, axis = a, at_max = false;
    if (to_max < nearest) nearest = to_max, axis = a, at_max = true;
  }
  Face face;
  face.W_normal = Eigen::Vector3d::Unit(axis) * (at_max ? 1.0 : -1.0);
  face.axis = axis;
  face.u_m = W_point[(axis + 1) % 3];
  face.v_m = W_point[(axis + 2) % 3];
  face.id = hashCombine(static_cast<uint32_t>(object), static_cast<uint32_t>(2 * axis + at_max));
  return face;
}

/// Texture of mean 0 and standard deviation 1 at full detail (less where
/// octaves fade) of a face at (u, v) [m], its octaves finer than the
/// footprint faded out.
double texture(uint32_t face_id, double u_m, double v_m, double footprint_m) {
  double sum = 0.0;
  double wavelength = kFinestTextureWavelengthM;
  for (int o = 0; o < kTextureOctaves; ++o, wavelength *= 2.0) {
    const double weight = std::clamp(
        (wavelength / footprint_m - kNoOctaveFootprints) / (kFullOctaveFootprints - kNoOctaveFootprints), 0.0, 1.0);
    if (weight > 0.0)
      sum += weight * valueNoise(u_m / wavelength, v_m / wavelength, hashCombine(face_id, static_cast<uint32_t>(o)));
  }
  return sum / (std::sqrt(static_cast<double>(kTextureOctaves)) * kValueNoiseStd);
}

/// texture() over a pixel's footprint that is @p stretch times longer along
/// the unit face direction (du, dv) than across it: the mean of samples
/// along that direction, each blurred by the footprint across (a pixel
/// averages a far ground's texture along the view, not across it, and the
/// matcher needs the texture across).
double stretchedTexture(const Face& face, double footprint_m, double stretch, double du, double dv) {
  const int samples = std::clamp(static_cast<int>(std::ceil(stretch)), 1, kMaxStretchSamples);
  const double length_m = footprint_m * stretch, blur_m = std::max(footprint_m, length_m / samples);
  double sum = 0.0;
  for (int i = 0; i < samples; ++i) {
    const double along_m = ((i + 0.5) / samples - 0.5) * length_m;
    sum += texture(face.id, face.u_m + along_m * du, face.v_m + along_m * dv, blur_m);
  }
  return sum / samples;
}

double shade(const Eigen::Vector3d& W_normal, const ImageAppearance& look) {
  return look.ambient + (1.0 - look.ambient) * std::max(0.0, W_normal.dot(look.W_sun.normalized()));
}

/// A pixel's footprint on a face: @p footprint_m across the view, @p stretch
/// times that along the unit face direction (du, dv).
struct Footprint {
  double footprint_m;
  double stretch = 1.0;
  double du = 1.0, dv = 0.0;
};

double faceGrey(const SyntheticScene& scene, int object, const Face& face, const Footprint& fp,
                const ImageAppearance& look) {
  if (object == SyntheticScene::kHitNothing) return look.sky_grey;
  double albedo = look.ground_albedo_grey, contrast = look.ground_contrast;
  if (object >= 0) {
    const size_t k = static_cast<size_t>(object);
    const bool textureless = k < scene.textureless.size() && scene.textureless[k];
    const uint32_t h = hash32(static_cast<uint32_t>(object) + 1u);
    albedo = textureless ? look.textureless_albedo_grey
                         : look.min_object_albedo_grey + look.object_albedo_span_grey * unitFromHash(h);
    contrast = textureless ? 0.0 : look.min_object_contrast + look.object_contrast_span * unitFromHash(hash32(h));
  }
  const double t = contrast > 0.0 ? stretchedTexture(face, fp.footprint_m, fp.stretch, fp.du, fp.dv) : 0.0;
  return albedo * shade(face.W_normal, look) * (1.0 + contrast * t);
}

/// The footprint on @p face of a pixel whose ray W_dir meets it after
/// covering @p across_m across the view: stretched along the ray's trace
/// on the face by 1 / cos(incidence).
Footprint footprintOn(const Face& face, const Eigen::Vector3d& W_dir, double across_m) {
  const double cosine = std::abs(W_dir.dot(face.W_normal));
  Footprint fp{across_m};
  fp.stretch = 1.0 / std::max(kMinIncidenceCosine, cosine);
  const Eigen::Vector3d W_trace = W_dir - W_dir.dot(face.W_normal) * face.W_normal;  // the ray's trace on the face
  const double du = W_trace[(face.axis + 1) % 3], dv = W_trace[(face.axis + 2) % 3], norm = std::hypot(du, dv);
  if (norm > 0.0) fp.du = du / norm, fp.dv = dv / norm;
  return fp;
}

}  // namespace

PixelHits castPixelRays(const SyntheticScene& scene, const StereoCameraModel& camera, const Eigen::Isometry3d& T_W_C) {
  const StereoCameraConfig& cfg = camera.config();
  const int tiles_x = (cfg.width_px + kTilePx - 1) / kTilePx, tiles_y = (cfg.height_px + kTilePx - 1) / kTilePx;
  std::vector<std::vector<int>> tile_boxes(static_cast<size_t>(tiles_x * tiles_y));
  const Eigen::Isometry3d T_C_W = T_W_C.inverse();
  for (size_t k = 0; k < scene.boxes.size(); ++k) {
    std::array<int, 4> r;
    if (!boxTiles(scene.boxes[k], T_C_W, cfg, tiles_x, tiles_y, &r)) continue;
    for (int ty = r[1]; ty <= r[3]; ++ty)
      for (int tx = r[0]; tx <= r[2]; ++tx)
        tile_boxes[static_cast<size_t>(ty * tiles_x + tx)].push_back(static_cast<int>(k));
  }
  PixelHits hits;
  hits.range_m.create(cfg.height_px, cfg.width_px, CV_64FC1);
  hits.object.create(cfg.height_px, cfg.width_px, CV_32SC1);
  const Eigen::Matrix3d R_W_C = T_W_C.linear();
  for (int ty = 0; ty < tiles_y; ++ty)
    for (int tx = 0; tx < tiles_x; ++tx) {
      const std::vector<int>& boxes = tile_boxes[static_cast<size_t>(ty * tiles_x + tx)];
      SyntheticScene tile;  // the tile's boxes in the scene's order: castRay's ties break alike
      tile.ground_height_m = scene.ground_height_m;
      for (int k : boxes) tile.boxes.push_back(scene.boxes[static_cast<size_t>(k)]);
      for (int y = ty * kTilePx; y < std::min(cfg.height_px, (ty + 1) * kTilePx); ++y)
        for (int x = tx * kTilePx; x < std::min(cfg.width_px, (tx + 1) * kTilePx); ++x) {
          int hit = SyntheticScene::kHitNothing;
          const Eigen::Vector3d W_dir = R_W_C * camera.rayThroughPixel(x, y).normalized();
          hits.range_m.at<double>(y, x) = tile.castRay(T_W_C.translation(), W_dir, &hit);
          hits.object.at<int>(y, x) = hit >= 0 ? boxes[static_cast<size_t>(hit)] : hit;
        }
    }
  return hits;
}

double surfaceGrey(const SyntheticScene& scene, int object, const Eigen::Vector3d& W_point, double footprint_m,
                   const ImageAppearance& look) {
  if (object == SyntheticScene::kHitNothing) return look.sky_grey;
  return faceGrey(scene, object, faceAt(scene, object, W_point), Footprint{footprint_m}, look);
}

cv::Mat renderGreyImage(const SyntheticScene& scene, const StereoCameraModel& camera, const Eigen::Isometry3d& T_W_C,
                        uint32_t noise_seed, const ImageAppearance& look, PixelHits* hits_out) {
  const PixelHits hits = castPixelRays(scene, camera, T_W_C);
  const StereoCameraConfig& cfg = camera.config();
  const double pixel_angle_rad = 1.0 / cfg.focal_length_px;
  std::mt19937 rng(noise_seed);
  std::normal_distribution<double> noise(0.0, look.sensor_noise_grey);
  cv::Mat image(cfg.height_px, cfg.width_px, CV_8UC1);
  for (int y = 0; y < cfg.height_px; ++y)
    for (int x = 0; x < cfg.width_px; ++x) {
      const int object = hits.object.at<int>(y, x);
      double grey = look.sky_grey;
      if (object != SyntheticScene::kHitNothing) {
        const Eigen::Vector3d W_dir = T_W_C.linear() * camera.rayThroughPixel(x, y).normalized();
        const double range = hits.range_m.at<double>(y, x);
        const Eigen::Vector3d W_point = T_W_C.translation() + range * W_dir;
        const Face face = faceAt(scene, object, W_point);
        grey = faceGrey(scene, object, face, footprintOn(face, W_dir, range * pixel_angle_rad), look);
      }
      image.at<uchar>(y, x) = cv::saturate_cast<uchar>(grey + noise(rng));
    }
  if (hits_out) *hits_out = hits;
  return image;
}

Eigen::Isometry3d rightCameraPose(const Eigen::Isometry3d& T_W_L, double baseline_m) {
  return T_W_L * Eigen::Translation3d(baseline_m, 0.0, 0.0);
}

}  // namespace stereo_occupancy
