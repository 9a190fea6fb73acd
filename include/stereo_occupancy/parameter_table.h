#pragma once
/// @file
/// The one table of a component's parameters. Each config struct lists its
/// parameters once, in forEachParameter(): the name (as the ROS parameter,
/// config/mapping.yaml, config/DisparityMapper.cfg and the README call it),
/// the unit, the valid range and the meaning, with the member that holds the
/// value. Defaults are the struct's initialisers. isValid() checks the
/// ranges from this table; the glue reads parameters by it; a test checks
/// that the YAML, the .cfg and the README say the same.

#include <cmath>
#include <cstdint>
#include <iomanip>
#include <sstream>
#include <string>
#include <type_traits>

namespace stereo_occupancy {

/// One parameter: name, unit, valid range (numbers only) and meaning.
struct ParameterSpec {
  const char* name;
  const char* unit;  ///< "" for none
  double min;        ///< valid values are [min, max], both included
  double max;
  const char* meaning;

  /// True if @p value lies in [min, max] (never for NaN).
  bool contains(double value) const { return value >= min && value <= max; }
  /// "[min, max]" as the README writes it.
  std::string rangeText() const {
    std::ostringstream s;
    s << std::setprecision(10) << "[" << min << ", " << max << "]";
    return s.str();
  }
};

/// A numeric parameter (double, int or unsigned) valid in [min, max].
constexpr ParameterSpec numberParameter(const char* name, const char* unit, double min, double max,
                                        const char* meaning) {
  return ParameterSpec{name, unit, min, max, meaning};
}

/// A parameter without a numeric range: a string, a flag or a choice of names.
constexpr ParameterSpec textParameter(const char* name, const char* meaning) {
  return ParameterSpec{name, "", NAN, NAN, meaning};
}

/// True for the value types that have a numeric range.
template <typename T>
constexpr bool kIsNumberParameter = std::is_arithmetic_v<T> && !std::is_same_v<T, bool>;

/// False, with "<name> must be in [min, max] (got <value>)" in @p why, if a
/// numeric parameter of @p config lies outside its table's range; Config
/// provides forEachParameter(Self&, F&&).
template <typename Config>
bool parametersInRange(const Config& config, std::string* why) {
  bool ok = true;
  Config::forEachParameter(config, [&](const ParameterSpec& spec, const auto& value) {
    using T = std::decay_t<decltype(value)>;
    if constexpr (kIsNumberParameter<T>) {
      if (ok && !spec.contains(static_cast<double>(value))) {
        ok = false;
        if (why) {
          std::ostringstream s;
          s << spec.name << " must be in " << spec.rangeText() << " (got " << value << ")";
          *why = s.str();
        }
      }
    }
  });
  return ok;
}

/// Sets the numeric parameter called @p name of @p config to @p value (not
/// range-checked: isValid() does that); false if @p config has no numeric
/// parameter of that name. For tools that take NAME=VALUE.
template <typename Config>
bool setNumberParameter(Config* config, const std::string& name, double value) {
  bool found = false;
  Config::forEachParameter(*config, [&](const ParameterSpec& spec, auto& member) {
    using T = std::decay_t<decltype(member)>;
    if constexpr (kIsNumberParameter<T>) {
      if (name == spec.name) {
        member = static_cast<T>(value);
        found = true;
      }
    }
  });
  return found;
}

}  // namespace stereo_occupancy
