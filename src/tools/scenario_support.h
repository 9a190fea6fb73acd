#pragma once
// The simulated flights by name for the command-line tools that fly them
// (simulate_flight and the bench's tools): apart from tool_support.h, so that
// a tool that flies none does not need the simulation library (bench/).

#include <stdexcept>
#include <string>

#include "stereo_occupancy/sim/flight_simulation.h"
#include "tool_support.h"

namespace stereo_occupancy {
namespace tools {

/// The named simulated flight, or a UsageError listing the names.
inline FlightScenario scenarioNamed(const std::string& name) {
  try {
    return makeScenario(name);
  } catch (const std::invalid_argument& e) {
    throw UsageError(e.what());
  }
}

}  // namespace tools
}  // namespace stereo_occupancy
