#include "stereo_occupancy/inverse_sensor_model.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>

#include "stereo_occupancy/stereo_camera_model.h"

namespace stereo_occupancy {

namespace {
constexpr double kSqrt2Pi = 2.5066282746310002;
}

const char* toString(SensorProfile profile) { return profile == SensorProfile::kSurface ? "surface" : "gaussian"; }

bool parseSensorProfile(const std::string& name, SensorProfile* profile) {
  if (name == "gaussian")
    *profile = SensorProfile::kGaussian;
  else if (name == "surface")
    *profile = SensorProfile::kSurface;
  else
    return false;
  return true;
}

bool InverseSensorModelConfig::isValid(std::string* why) const {
  if (!parametersInRange(*this, why)) return false;
  if (!(p_sky >= p_free)) {
    if (why) *why = "p_sky must be >= p_free";
    return false;
  }
  static_assert(LogOddsTable::kTailSigmas == 3.0 && LogOddsTable::kFrontSigmas == 4.0,
                "the table's tail_sigmas and free_gap_sigmas ranges end where LogOddsTable's profile does");
  return true;
}

double InverseSensorModel::peakProbability(double delta_l_m) const {
  return std::min(0.5 + config_.k_m / (delta_l_m * kSqrt2Pi), config_.p_max);
}

double InverseSensorModel::probability(double l_m, double l_p_m, double delta_l_m) const {
  const double p_occ = occupancyPrior(l_m, l_p_m);  // eq. 10
  const double s = (l_m - l_p_m) / delta_l_m;
  if (config_.profile == SensorProfile::kSurface) {
    if (s == 0.0) return config_.p_hit;
    return s < -config_.free_gap_sigmas ? config_.p_free : 0.5;
  }
  // Beyond a shortened tail: no information (the paper's tail, kTailSigmas,
  // is where the table ends; the exact model goes on).
  if (config_.tail_sigmas < LogOddsTable::kTailSigmas && s > config_.tail_sigmas) return 0.5;
  // Eq. 9, with the amplitude k/(Δl√2π) + 0.5 capped at p_max.
  return p_occ + (peakProbability(delta_l_m) - p_occ) * std::exp(-0.5 * s * s);
}

double InverseSensorModel::logOdds(double l_m, double l_p_m, double delta_l_m) const {
  const double p = probability(l_m, l_p_m, delta_l_m);
  return std::log(p / (1.0 - p));  // eq. 8
}

double InverseSensorModel::logOddsHat(double l_m, double l_p_m, double delta_l_m, double cell_size_m) const {
  // Eq. 11: max over [l - c/2, l + c/2]; P is unimodal with its mode at l_p.
  const double nearest = std::clamp(l_p_m, l_m - 0.5 * cell_size_m, l_m + 0.5 * cell_size_m);
  return logOdds(nearest, l_p_m, delta_l_m);
}

double InverseSensorModel::logOddsHatSampled(double l_m, double l_p_m, double delta_l_m, double cell_size_m,
                                             int samples) const {
  double best = -std::numeric_limits<double>::infinity();
  for (int i = 0; i < samples; ++i) {
    const double l = l_m - 0.5 * cell_size_m + cell_size_m * i / (samples - 1);
    best = std::max(best, logOdds(l, l_p_m, delta_l_m));
  }
  return best;
}

namespace {
/// RangeProfile::step_sample of a table: the last sample of a nonzero value
/// in rows that hold it up to there and +0 after it, all rows alike; -1 if
/// the rows are not so.
int lastSampleOfStep(const std::vector<float>& values, int row_length) {
  const float* first = values.data();
  if (values.empty() || first[0] == 0.0f) return -1;
  int step = 0;
  while (step + 1 < row_length && first[step + 1] == first[0]) ++step;
  for (int j = step + 1; j < row_length; ++j)
    if (first[j] != 0.0f || std::signbit(first[j])) return -1;
  for (size_t i = static_cast<size_t>(row_length); i < values.size(); i += static_cast<size_t>(row_length))
    if (std::memcmp(first, &values[i], sizeof(float) * static_cast<size_t>(row_length)) != 0) return -1;
  return step + 1 < row_length ? step : -1;
}
}  // namespace

LogOddsTable::LogOddsTable(const InverseSensorModel& model, double cell_size_m)
    : cell_size_m_(cell_size_m),
      tail_sigmas_(model.config().profile == SensorProfile::kSurface
                       ? 1.0f / kSamplesPerSigma  // the measurement's own cell only
                       : static_cast<float>(model.config().tail_sigmas)) {
  const auto& cfg = model.config();
  k_over_sqrt_2pi_ = static_cast<float>(cfg.k_m / kSqrt2Pi);
  peak_max_ = static_cast<float>(cfg.p_max - 0.5);
  rows_per_peak_ = static_cast<float>((kPeakRows - 1) / (cfg.p_max - 0.5));
  const int samples = static_cast<int>((kFrontSigmas + kTailSigmas) * kSamplesPerSigma);
  row_length_ = samples + 2;  // one sample of padding for the interpolation at the tail
  free_log_odds_ = static_cast<float>(model.freeLogOdds());
  hit_log_odds_ =
      cfg.profile == SensorProfile::kSurface ? static_cast<float>(std::log(cfg.p_hit / (1.0 - cfg.p_hit))) : 0.0f;
  sky_log_odds_ = cfg.profile == SensorProfile::kSurface
                      ? std::nextafter(static_cast<float>(std::log(cfg.p_sky / (1.0 - cfg.p_sky))),
                                       -std::numeric_limits<float>::infinity())
                      : free_log_odds_;
  // One extra row so that the row above the last one exists for the interpolation.
  values_.resize(static_cast<size_t>(kPeakRows + 1) * row_length_);
  for (int r = 0; r <= kPeakRows; ++r) {
    const double peak = 0.5 + std::min(r, kPeakRows - 1) * (cfg.p_max - 0.5) / (kPeakRows - 1);
    float* row = &values_[static_cast<size_t>(r) * row_length_];
    for (int j = 0; j < row_length_; ++j) {
      const double t = -kFrontSigmas + static_cast<double>(j) / kSamplesPerSigma;  // e / Δl
      if (cfg.profile == SensorProfile::kSurface) {  // the hit is RangeProfile::hit_log_odds
        const double p = t < -cfg.free_gap_sigmas ? cfg.p_free : 0.5;
        row[j] = static_cast<float>(std::log(p / (1.0 - p)));
        continue;
      }
      const double p_occ = t <= 0.0 ? cfg.p_min : 0.5;                   // eq. 10
      const double p = p_occ + (peak - p_occ) * std::exp(-0.5 * t * t);  // eq. 9
      row[j] = static_cast<float>(std::log(p / (1.0 - p)));              // eq. 8
    }
  }
  step_sample_ = lastSampleOfStep(values_, row_length_);
}

RangeProfile LogOddsTable::profile(float l_p_m, float delta_l_m) const {
  delta_l_m = usableDeltaL(delta_l_m);
  RangeProfile p;
  // Height of the peak above 0.5 (eq. 9), capped at p_max - 0.5.
  const float inv_delta_l = 1.0f / delta_l_m;
  const float height = std::min(k_over_sqrt_2pi_ * inv_delta_l, peak_max_);
  const float x = height * rows_per_peak_;
  const int r = std::min(static_cast<int>(x), kPeakRows - 1);
  p.row = &values_[static_cast<size_t>(r) * row_length_];
  p.row_length = row_length_;
  p.row_weight = x - static_cast<float>(r);
  p.l_p_m = l_p_m;
  p.samples_per_m = kSamplesPerSigma * inv_delta_l;
  p.half_cell_m = static_cast<float>(0.5 * cell_size_m_);
  p.front_m = frontOf(delta_l_m);
  p.row_origin_m = -kFrontSigmas * delta_l_m;
  p.tail_m = tailOf(delta_l_m);
  p.free_log_odds = free_log_odds_;
  p.hit_log_odds = hit_log_odds_;
  p.step_sample = step_sample_;
  return p;
}

RangeProfile LogOddsTable::freeProfile() const {
  RangeProfile p = profile(std::numeric_limits<float>::infinity(), 1.0f);
  p.tail_m = 0.0f;
  p.free_log_odds = sky_log_odds_;
  p.hit_log_odds = 0.0f;  // no range, no hit
  return p;
}

RangeProfile measuredProfile(const StereoCameraModel& camera, const LogOddsTable& table, double ray_norm, float d_px) {
  const MeasuredRange m = measuredRange(camera, ray_norm, d_px);
  return table.profile(m.l_p_m, m.delta_l_m);
}

RangeProfile pixelProfile(const StereoCameraModel& camera, const LogOddsTable& table, double x_px, double y_px,
                          float d_px) {
  return measuresRange(camera, d_px) ? measuredProfile(camera, table, camera.rayThroughPixel(x_px, y_px).norm(), d_px)
                                     : table.freeProfile();
}

}  // namespace stereo_occupancy
