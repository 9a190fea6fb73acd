#pragma once
// Argument parsing and error reporting shared by the command-line tools: a
// bad argument or file ends a tool with one line "<tool>: error: ..." on
// stderr and exit status 2 (bad arguments) or 1 (a failure while running),
// never with an uncaught exception.

#include <cmath>
#include <cstdlib>
#include <exception>
#include <iostream>
#include <map>
#include <stdexcept>
#include <string>

#include "stereo_occupancy/disparity_drawer.h"
#include "stereo_occupancy/parameter_table.h"

namespace stereo_occupancy {
namespace tools {

/// A bad command line: exit status 2.
struct UsageError : std::invalid_argument {
  using std::invalid_argument::invalid_argument;
};

/// @p text as a finite number, or a UsageError naming @p option.
inline double parseNumber(const std::string& option, const std::string& text) {
  char* end = nullptr;
  const double v = std::strtod(text.c_str(), &end);
  if (text.empty() || *end != '\0' || !std::isfinite(v))
    throw UsageError(option + " expects a finite number, got '" + text + "'");
  return v;
}

/// @p text as a whole number in [lo, hi], or a UsageError naming @p option.
inline long parseWhole(const std::string& option, const std::string& text, long lo, long hi) {
  char* end = nullptr;
  const long v = std::strtol(text.c_str(), &end, 10);
  if (text.empty() || *end != '\0' || v < lo || v > hi)
    throw UsageError(option + " expects a whole number in [" + std::to_string(lo) + ", " + std::to_string(hi) +
                     "], got '" + text + "'");
  return v;
}

/// The value after option argv[i] (advancing i), or a UsageError.
inline std::string nextValue(int argc, char** argv, int* i) {
  if (*i + 1 >= argc) throw UsageError(std::string(argv[*i]) + " needs a value");
  return argv[++*i];
}

/// The NAME=VALUE after option argv[i] (advancing i) into (*values)[NAME],
/// VALUE a finite number; or a UsageError naming the option.
inline void addNameValue(int argc, char** argv, int* i, std::map<std::string, double>* values) {
  const std::string option = argv[*i];
  const std::string kv = nextValue(argc, argv, i);
  const size_t eq = kv.find('=');
  if (eq == std::string::npos || eq == 0) throw UsageError(option + " takes NAME=VALUE");
  (*values)[kv.substr(0, eq)] = parseNumber(option, kv.substr(eq + 1));
}

/// The sensor model parameters given with --model (NAME=VALUE, by name) into
/// @p config; a UsageError for an unknown name or a value out of range.
inline void applyModelValues(const std::map<std::string, double>& values, DrawingConfig* config) {
  for (const auto& [name, value] : values)
    if (!setNumberParameter(&config->sensor_model, name, value))
      throw UsageError("--model: unknown name '" + name + "'");
  std::string why;
  if (!config->isValid(&why)) throw UsageError("--model: " + why);
}

/// Runs a tool's body; turns exceptions into one error line and an exit status.
template <typename Body>
int runTool(const char* name, Body&& body) {
  try {
    return body();
  } catch (const UsageError& e) {
    std::cerr << name << ": error: " << e.what() << " (see --help)" << std::endl;
    return 2;
  } catch (const std::exception& e) {
    std::cerr << name << ": error: " << e.what() << std::endl;
    return 1;
  }
}

}  // namespace tools
}  // namespace stereo_occupancy
