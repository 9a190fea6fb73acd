#pragma once
/// @file
/// Inverse sensor model of one disparity pixel in log-odds (Andert 2009,
/// section IV, eqs. 8-11) and the lookup table that serves it to the drawing
/// algorithms.

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "stereo_occupancy/parameter_table.h"
#include "stereo_occupancy/stereo_camera_model.h"

namespace stereo_occupancy {

/// The shape of one measurement's profile along its ray.
enum class SensorProfile {
  /// The paper's eqs. 9-10: a Gaussian of width Δl around l_p, rising from
  /// p_min in front and falling to 0.5 behind (occupied from about 1.6 Δl in
  /// front of l_p to tail_sigmas·Δl behind it).
  kGaussian,
  /// Occupied (p_hit) only in the cell that holds the measured point (line
  /// drawing) or whose window holds l_p (ray tracing), no information in a
  /// gap of free_gap_sigmas·Δl in front of it (where the surface may truly
  /// be, given the range noise), free (p_free) before the gap, nothing
  /// behind: a hit makes no slab of phantom obstacles around the surface.
  kSurface,
};

/// "gaussian" or "surface".
const char* toString(SensorProfile profile);
/// Parses a name given by toString().
bool parseSensorProfile(const std::string& name, SensorProfile* profile);

/// Parameters of eqs. 9-10 plus the clamp that keeps eq. 9 a probability.
struct InverseSensorModelConfig {
  SensorProfile profile = SensorProfile::kGaussian;
  double k_m = 0.1;     ///< k, significance of one measurement [m] (eq. 9)
  double p_min = 0.35;  ///< occupancy probability of free space in front of a measurement (eq. 10)
  /// Cap on the peak probability P(l_p). Eq. 9 peaks at 0.5 + k/(Δl√(2π)),
  /// which reaches 1 for Δl <= k·2/√(2π) (below ~5.8 m with the paper's
  /// camera). The peak amplitude is capped at p_max, so the Gaussian keeps its
  /// shape and P stays in [p_min, p_max] ⊂ (0, 1) for every range.
  double p_max = 0.9;
  /// How far behind the peak a measurement speaks, in units of Δl: beyond
  /// l_p + c/2 + tail_sigmas·Δl its cells are left untouched. 3 is the
  /// paper's Gaussian down to 1 % of its height; 0 keeps only the
  /// measurement's own cell (nothing behind a surface is ever seen).
  double tail_sigmas = 3.0;
  /// kSurface: occupancy probability of the cell that holds the measurement.
  double p_hit = 0.68;
  /// kSurface: occupancy probability of the free space before the gap.
  double p_free = 0.3;
  /// kSurface: occupancy probability along a ray that measured no range (zero
  /// disparity: sky, or beyond the range), at least p_free; 0.5 says nothing.
  /// Such a ray misses what is too thin to resolve, but weaker sky evidence
  /// (0.45) left more noise behind thin objects than it saved wires from
  /// being called free (docs/quality.md), so it defaults to p_free.
  double p_sky = 0.3;
  /// kSurface: the gap in front of l_p without information, in units of Δl.
  double free_gap_sigmas = 1.0;
  /// kSurface: within this many cells (Chebyshev) of a cell the same image
  /// measured as occupied, a ray without a range says nothing. A thin wire
  /// or trunk is matched in some pixels and missed in their neighbours, whose
  /// sky rays would otherwise call its cells free (docs/quality.md). 0: off.
  int sky_guard_cells = 1;
  /// kSurface: the gap says nothing only within this many cells (Chebyshev)
  /// of a cell the same image measured as occupied; farther from every
  /// measured cell it is free space (p_free). A noise hit in front of a
  /// surface lies in the gaps of later views of that surface and was never
  /// cleared (docs/quality.md). 0 (default): off, the whole gap says
  /// nothing. Off while it is not measured on the flights: with one hit per
  /// block, kLinePyramidBounded's far line covered a nearer obstacle with
  /// its gap and the guard freed it; every pixel's hit now keeps that post
  /// (docs/quality.md).
  int gap_guard_cells = 0;
  /// kSurface: within this many cells (Chebyshev) of a cell the same image
  /// measured as occupied, free space says nothing, unless it lies in front
  /// of that cell as the camera sees it. A ray that passes beside a surface
  /// on its way to what lies behind calls the surface's edge cells free where
  /// a real matcher's disparities (fattened or thinned at depth edges) or the
  /// cells' corners put no hit; on the real stereo pairs the guard leaves
  /// 0.05-0.6 of the surface cells called free without it
  /// (docs/quality_analysis.md). In front of a surface, free space still
  /// clears earlier noise hits. 0: off.
  int edge_guard_cells = 1;

  /// The parameters (parameter_table.h): f(spec, member) for each.
  template <typename Self, typename F>
  static void forEachParameter(Self& c, F&& f) {
    f(textParameter("sensor_profile", "a measurement's profile along its ray: gaussian (eqs. 9-10) or surface"),
      c.profile);
    f(numberParameter("p_hit", "", 0.51, 0.99, "surface: probability of the cell holding the measurement"), c.p_hit);
    f(numberParameter("p_free", "", 0.01, 0.49, "surface: probability of the free space before the gap"), c.p_free);
    f(numberParameter("p_sky", "", 0.01, 0.5, "surface: probability along a ray without a range; at least p_free"),
      c.p_sky);
    f(numberParameter("free_gap_sigmas", "Δl", 0.0, 4.0, "surface: no information this far before the measurement"),
      c.free_gap_sigmas);
    f(numberParameter("sky_guard_cells", "cells", 0, 2,
                      "surface: a ray without a range says nothing this near a cell the image measured"),
      c.sky_guard_cells);
    f(numberParameter("gap_guard_cells", "cells", 0, 2,
                      "surface: the gap says nothing only this near a cell the image measured; 0: everywhere"),
      c.gap_guard_cells);
    f(numberParameter("edge_guard_cells", "cells", 0, 1,
                      "surface: free space says nothing beside (not in front of) a cell the image measured"),
      c.edge_guard_cells);
    f(numberParameter("tail_sigmas", "Δl", 0.0, 3.0, "gaussian: how far behind the peak a measurement speaks"),
      c.tail_sigmas);
    f(numberParameter("k_m", "m", 0.001, 10.0, "significance k of one measurement (eq. 9)"), c.k_m);
    f(numberParameter("p_min", "", 0.01, 0.49, "free-space probability (eq. 10)"), c.p_min);
    f(numberParameter("p_max", "", 0.51, 0.99, "cap of the peak probability"), c.p_max);
  }

  /// The ranges of forEachParameter(), and p_sky >= p_free.
  bool isValid(std::string* why = nullptr) const;
  bool operator==(const InverseSensorModelConfig& o) const {
    return profile == o.profile && k_m == o.k_m && p_min == o.p_min && p_max == o.p_max &&
           tail_sigmas == o.tail_sigmas && p_hit == o.p_hit && p_free == o.p_free && p_sky == o.p_sky &&
           free_gap_sigmas == o.free_gap_sigmas && sky_guard_cells == o.sky_guard_cells &&
           gap_guard_cells == o.gap_guard_cells && edge_guard_cells == o.edge_guard_cells;
  }
};

/// Exact evaluation of the model; the drawing algorithms use LogOddsTable.
class InverseSensorModel {
 public:
  explicit InverseSensorModel(const InverseSensorModelConfig& config) : config_(config) {}

  const InverseSensorModelConfig& config() const { return config_; }

  /// P_occ(l) of eq. 10: p_min in front of the measurement, 0.5 behind.
  double occupancyPrior(double l_m, double l_p_m) const { return l_m <= l_p_m ? config_.p_min : 0.5; }

  /// Peak probability at l = l_p: 0.5 + k / (Δl √(2π)) (eq. 9), capped at p_max.
  double peakProbability(double delta_l_m) const;

  /// P(s(l)) of eq. 9 for a measurement at range l_p with uncertainty Δl.
  double probability(double l_m, double l_p_m, double delta_l_m) const;

  /// L(s(l)) = ln(P / (1 - P)) (eq. 8).
  double logOdds(double l_m, double l_p_m, double delta_l_m) const;

  /// L̂(s(l)) of eq. 11: the maximum of L over the cell-wide window
  /// [l - c/2, l + c/2]. P is unimodal in l with its mode at l_p (it rises
  /// from p_min to the peak in front and falls to 0.5 behind), so the maximum
  /// is L at the window point nearest to l_p; this is exact, and
  /// logOddsHatSampled() is the paper's dense-sampling approximation of it.
  double logOddsHat(double l_m, double l_p_m, double delta_l_m, double cell_size_m) const;

  /// Eq. 11 by dense sampling of the window with @p samples points.
  double logOddsHatSampled(double l_m, double l_p_m, double delta_l_m, double cell_size_m, int samples = 10001) const;

  /// Log-odds of free space, ln(p / (1 - p)) of p_min (p_free for kSurface).
  double freeLogOdds() const {
    const double p = config_.profile == SensorProfile::kSurface ? config_.p_free : config_.p_min;
    return std::log(p / (1.0 - p));
  }

 private:
  InverseSensorModelConfig config_;
};

/// L̂ along one ray, as served by LogOddsTable: a view into two table rows.
/// Cheap to copy; valid while the table lives.
struct RangeProfile {
  /// sample() keeps x within [kMinSampleX, kMaxSampleX]: its reads stay in
  /// the row's samples and padding (LogOddsTable checks the bounds).
  static constexpr float kMinSampleX = -0.99999994f;           // the float next to -1 towards 0
  static constexpr float kMaxSampleX = 224.9999847412109375f;  // the float next to the last sample + 1 towards 0
  const float* row = nullptr;                            ///< row of the peak probability just below this measurement's
  int row_length = 0;                                    ///< offset to the next row (just above)
  float row_weight = 0.0f;                               ///< interpolation weight of the next row
  float l_p_m = std::numeric_limits<float>::infinity();  ///< measured range (inf: free to max range)
  float samples_per_m = 0.0f;                            ///< table samples per metre of offset
  float half_cell_m = 0.0f;
  float front_m = 0.0f;       ///< offsets u = l - l_p below this are plain free space
  float row_origin_m = 0.0f;  ///< offset e (window removed) of a row's first sample
  float tail_m = 0.0f;        ///< offsets above this carry no information (not drawn)
  float free_log_odds = 0.0f;
  /// kSurface: log-odds of p_hit, the measurement's own cell; 0 for kGaussian,
  /// whose peak is in the table. The table's rows hold no hit for kSurface:
  /// at() adds it in the cell's window, a line drawing draws it into the cell
  /// that holds the measured point (LineDrawer).
  float hit_log_odds = 0.0f;
  /// The table's rows as one step (kSurface: each row free up to this
  /// sample and 0 after it, every row alike), or -1 (kGaussian): see stepSample().
  int step_sample = -1;

  /// Range up to which a line must be drawn [m].
  float endRange() const { return l_p_m + tail_m; }

  /// True if the measurement's hit is drawn apart from the table (kSurface).
  bool hasPointHit() const { return hit_log_odds > 0.0f; }

  /// L̂ at range l [m]; requires l - l_p <= tail_m.
  float at(float l_m) const {
    if (hasPointHit() && std::abs(l_m - l_p_m) <= half_cell_m) return hit_log_odds;  // the window holds l_p
    return tableAt(l_m);
  }

  /// at() without a kSurface hit: the table alone.
  float tableAt(float l_m) const {
    const float u = l_m - l_p_m;
    if (!(u >= front_m)) return free_log_odds;  // also for l_p = inf
    // Eq. 11: the cell-wide window around l reaches to the point nearest l_p.
    const float e = u > half_cell_m ? u - half_cell_m : (u < -half_cell_m ? u + half_cell_m : 0.0f);
    return sample((e - row_origin_m) * samples_per_m);
  }

  /// The table at fractional sample x = (e - row_origin_m) · samples_per_m,
  /// 0 <= x <= (kFrontSigmas + kTailSigmas) · kSamplesPerSigma. An x
  /// outside (-1, that + 1) (float cancellation at a Δl far below the range's
  /// rounding, from a hostile camera; NaN) reads the table's nearest end
  /// instead of memory beyond it.
  float sample(float x) const {
    x = std::min(kMaxSampleX, std::max(kMinSampleX, x));  // NaN: kMinSampleX
    const int j = static_cast<int>(x);
    const float frac = x - static_cast<float>(j);
    const float* r0 = row + j;
    const float* r1 = r0 + row_length;
    const float v0 = r0[0] + frac * (r0[1] - r0[0]);
    const float v1 = r1[0] + frac * (r1[1] - r1[0]);
    return v0 + row_weight * (v1 - v0);
  }

  /// sample(x) for step_sample >= 0 and x >= 0, bit for bit, without the
  /// interpolation but at the step: below it both samples and both rows hold
  /// the free value, above it 0, and adding frac · 0 or row_weight · 0
  /// changes nothing. Compared in float, not by the sample's index, so that
  /// no x (NaN goes to sample()) reads beyond the table.
  float stepSample(float x) const {
    const float step = static_cast<float>(step_sample);
    return x < step ? row[0] : (x >= step + 1.0f ? 0.0f : sample(x));
  }
};

/// Lookup table of eq. 11, built once per (model, cell size) set-up.
///
/// L̂ depends on the offset u = l - l_p, on Δl and on c. Removing the
/// cell-wide window from u (eq. 11, see InverseSensorModel::logOddsHat) leaves
/// e; in units of Δl, L(e) depends only on the peak probability
/// A = min(0.5 + k/(Δl√2π), p_max). The table has kPeakRows rows evenly spaced
/// in A from 0.5 to p_max, each sampling L from e = -kFrontSigmas·Δl to
/// +kTailSigmas·Δl with kSamplesPerSigma samples per Δl; look-ups interpolate
/// bilinearly. Beyond the front the value is the free-space log-odds; beyond
/// the tail (the model's tail_sigmas, at most kTailSigmas, where P - 0.5 <
/// 1.1 % of the peak height) cells are left untouched.
class LogOddsTable {
 public:
  static constexpr float kFrontSigmas = 4.0f;
  static constexpr float kTailSigmas = 3.0f;
  static constexpr int kSamplesPerSigma = 32;
  static constexpr int kPeakRows = 41;
  static_assert(RangeProfile::kMaxSampleX < (kFrontSigmas + kTailSigmas) * kSamplesPerSigma + 1.0f &&
                    RangeProfile::kMaxSampleX > (kFrontSigmas + kTailSigmas) * kSamplesPerSigma,
                "sample() reads samples j and j + 1 <= the row's padding");
  /// Δl below this is taken as this [m] (eq. 7 gives 6e-4 m at 0.5 m range).
  static constexpr float kMinDeltaL = 1e-6f;
  /// Largest Δl a profile is built with [m]: far beyond any grid, and small
  /// enough that its samples per metre and its window's ends stay finite
  /// (a camera of tiny f gives rays of huge range and Δl = inf).
  static constexpr float kMaxDeltaL = 1e9f;

  LogOddsTable(const InverseSensorModel& model, double cell_size_m);

  /// Profile of a measurement at range l_p with uncertainty Δl > 0 [m].
  RangeProfile profile(float l_p_m, float delta_l_m) const;

  /// Profile of a zero-disparity pixel: free space along the whole ray.
  RangeProfile freeProfile() const;

  /// profile(l_p, Δl).tail_m without the rest of the profile: beyond l_p
  /// plus this a measurement says nothing [m].
  float tailOf(float delta_l_m) const { return static_cast<float>(0.5 * cell_size_m_) + tail_sigmas_ * delta_l_m; }

  /// profile(l_p, Δl).l_p_m + front_m without the rest of the profile: up to
  /// this range the measurement's ray is plain free space [m].
  float frontRange(float l_p_m, float delta_l_m) const { return l_p_m + frontOf(usableDeltaL(delta_l_m)); }

  double cellSize() const { return cell_size_m_; }
  float freeLogOdds() const { return free_log_odds_; }
  /// RangeProfile::hit_log_odds of every measured profile: log-odds of p_hit for kSurface, else 0.
  float hitLogOdds() const { return hit_log_odds_; }
  /// Log-odds along a ray that measured no range. For the surface profile one
  /// float step below p_sky's, so that a cell a measured ray also crosses
  /// holds that ray's value (the max) and silenceNearOccupied() can tell the two apart.
  float skyLogOdds() const { return sky_log_odds_; }

 private:
  /// Δl as a profile takes it: within [kMinDeltaL, kMaxDeltaL], NaN as kMaxDeltaL.
  static float usableDeltaL(float delta_l_m) {
    // A disparity near the matcher's largest at a very short range gives a Δl
    // that float rounds to 0, a hostile camera one of inf: the table's samples
    // per metre and the window's ends must stay finite (NaN fails both tests).
    delta_l_m = std::clamp(delta_l_m, kMinDeltaL, kMaxDeltaL);
    return delta_l_m >= kMinDeltaL ? delta_l_m : kMaxDeltaL;
  }
  /// RangeProfile::front_m for a usable Δl [m].
  float frontOf(float delta_l_m) const { return -static_cast<float>(0.5 * cell_size_m_) - kFrontSigmas * delta_l_m; }

  double cell_size_m_;
  float tail_sigmas_;  ///< InverseSensorModelConfig::tail_sigmas, at most kTailSigmas
  float k_over_sqrt_2pi_;
  float peak_max_;       ///< p_max - 0.5
  float rows_per_peak_;  ///< (kPeakRows - 1) / (p_max - 0.5)
  int row_length_;
  float free_log_odds_;
  float hit_log_odds_;  ///< RangeProfile::hit_log_odds
  float sky_log_odds_;  ///< of freeProfile(): a ray that measured no range
  std::vector<float> values_;
  int step_sample_ = -1;  ///< RangeProfile::step_sample
};

/// True if disparity @p d_px measures a range; false for zero and for a
/// positive one whose depth lies beyond a thousand times the maximum range
/// (its Δl would overflow): such a pixel sees free space to the range.
inline bool measuresRange(const StereoCameraModel& camera, float d_px) { return d_px > 1e-3 * camera.farDisparity(); }

/// A measurement along its ray: range l_p and its uncertainty Δl.
struct MeasuredRange {
  float l_p_m;      ///< l_p [m] (eq. 6)
  float delta_l_m;  ///< Δl_p [m] (eq. 7)
};

/// The range of disparity d > 0 (measuresRange() holds) along a ray with
/// @p ray_norm = |p_c| / z_c (eq. 2: the norm of (x - c_x, y - c_y, f) / f).
inline MeasuredRange measuredRange(const StereoCameraModel& camera, double ray_norm, float d_px) {
  const double z = camera.depthFromDisparity(d_px);                                       // eq. 1
  const double l_p = z * ray_norm;                                                        // eqs. 2, 6
  return {static_cast<float>(l_p), static_cast<float>(camera.rangeUncertainty(z, l_p))};  // eqs. 4, 7
}

/// The profile of L̂ along a pixel's ray for a disparity d > 0 for which
/// measuresRange() holds; @p ray_norm as for measuredRange().
RangeProfile measuredProfile(const StereoCameraModel& camera, const LogOddsTable& table, double ray_norm, float d_px);

/// measuredProfile()'s l_p_m + front_m alone (LogOddsTable::frontRange()).
inline float measuredFrontRange(const StereoCameraModel& camera, const LogOddsTable& table, double ray_norm,
                                float d_px) {
  const MeasuredRange m = measuredRange(camera, ray_norm, d_px);
  return table.frontRange(m.l_p_m, m.delta_l_m);
}

/// measuredProfile(), or free space up to the maximum range (freeProfile())
/// for a disparity that measures no range.
RangeProfile pixelProfile(const StereoCameraModel& camera, const LogOddsTable& table, double x_px, double y_px,
                          float d_px);

}  // namespace stereo_occupancy
