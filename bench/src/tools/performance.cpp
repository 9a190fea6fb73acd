// performance: the performance issue's figures in one run, on the Table I
// frame (640x480, b = 0.3 m, f = 700 px, 25 m range) at 0.25 m cells, one
// thread unless --threads N: each stage of the mapper's path timed alone (median and min-max of
// N runs), and OctoMap's insertPointCloud on the same frame for comparison.
// A benchmark: it prints figures and asserts nothing.
//
// --only STAGE runs one stage N times and prints nothing else (for
// valgrind --tool=callgrind).

#include <octomap/octomap.h>

#include <algorithm>
#include <chrono>
#include <functional>
#include <iomanip>
#include <iostream>
#include <map>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "drawing_benchmark.h"
#include "scenario_support.h"
#include "stereo_occupancy/disparity_drawer.h"
#include "stereo_occupancy/grid_update.h"
#include "stereo_occupancy/map_accumulator.h"
#include "stereo_occupancy/sim/flight_simulation.h"
#include "stereo_occupancy/sim/synthetic_scene.h"
#include "stereo_occupancy/stage_times.h"
#include "stereo_occupancy/time_statistics.h"
#include "tool_support.h"
#include "whole_path.h"

namespace so = stereo_occupancy;

namespace {

using Clock = std::chrono::steady_clock;

std::string threadsText(int threads) { return threads == 1 ? "one thread" : std::to_string(threads) + " threads"; }

struct Timing {
  std::vector<double> ms;  // sorted
  double median() const { return ms[ms.size() / 2]; }
  std::string text() const {
    std::ostringstream s;
    s << std::fixed << std::setprecision(median() < 10 ? 3 : 1) << median() << " (" << ms.front() << "-" << ms.back()
      << ")";
    return s.str();
  }
};

/// Starts the fusion's class change recording on @p map, if @p on, past the
/// first "all" (which would skip it), as the distance field's feed does.
void recordChanges(so::MapAccumulator* map, bool on) {
  map->recordClassChanges(on);
  bool all = false;
  map->takeClassChanges(&all);
}

/// Times @p body @p repeats times; @p setup runs before each, untimed.
Timing timeIt(int repeats, const std::function<void()>& setup, const std::function<void()>& body) {
  Timing t;
  for (int r = 0; r < repeats; ++r) {
    setup();
    const auto t0 = Clock::now();
    body();
    t.ms.push_back(std::chrono::duration<double, std::milli>(Clock::now() - t0).count());
  }
  std::sort(t.ms.begin(), t.ms.end());
  return t;
}

/// The core of the mapper's path (shape and clear the grid, pyramids,
/// drawing, blur as configured: off by default, encoding) on every frame of
/// a simulated flight, per algorithm: the nodelet's work without ROS. With
/// @p pace_ms > 0 the thread sleeps that long before each frame, as a mapper
/// between its camera's images (a 10 Hz camera: 100 ms): what the caches and
/// the CPU's idle states cost a frame that arrives after a pause.
int flightPath(const std::string& scenario_name, long pace_ms, int threads, bool spans,
               const std::map<std::string, double>& model_values) {
  const so::FlightScenario scenario = so::tools::scenarioNamed(scenario_name);
  std::vector<cv::Mat> images;
  for (size_t i = 0; i < scenario.T_W_B.size(); ++i) images.push_back(so::renderStereoFrame(scenario, i, 1));
  std::cout << "Flight '" << scenario_name << "': " << images.size()
            << " frames, 640x480, 0.25 m cells, 25 m range, no blur; " << threadsText(threads)
            << (pace_ms > 0 ? "; a pause of " + std::to_string(pace_ms) + " ms before each frame" : std::string())
            << ".\nPer frame: grid preparation + pyramids + drawing + encoding, and the fusion of the update into "
               "the flight's map (the accumulator's work) [ms].\n\n"
               "| algorithm | mean | median | p99 | max | fusion mean | median | p99 | max |\n"
               "|---|---:|---:|---:|---:|---:|---:|---:|---:|\n";
  for (so::DrawingAlgorithm algorithm : {so::DrawingAlgorithm::kLinePyramid, so::DrawingAlgorithm::kRayTracePyramid,
                                         so::DrawingAlgorithm::kLinePyramidBounded}) {
    // The paper's pyramids with the paper's profile; the bounded one as the mapper draws it.
    const bool mapper = algorithm == so::DrawingConfig::mapperDefaults().algorithm;
    so::DrawingConfig config = mapper ? so::DrawingConfig::mapperDefaults() : so::DrawingConfig();
    config.algorithm = algorithm;
    config.threads = threads;
    config.surface_spans = spans;
    if (mapper) so::tools::applyModelValues(model_values, &config);
    so::DisparityDrawer drawer(scenario.camera, config);
    so::LocalGrid grid;
    so::GridUpdate update;
    so::MapAccumulatorConfig map_config;
    map_config.threads = threads;
    so::MapAccumulator map(map_config);
    std::vector<double> ms, fusion_ms;
    for (size_t i = 0; i < images.size(); ++i) {
      const Eigen::Isometry3d T_W_C = scenario.cameraPose(i);
      if (pace_ms > 0) std::this_thread::sleep_for(std::chrono::milliseconds(pace_ms));
      const auto t0 = Clock::now();
      drawer.draw(images[i], T_W_C, &grid);
      so::encodeGridUpdate(grid, T_W_C.translation(), &update);
      const auto t1 = Clock::now();
      map.integrate(update);  // the accumulator's work, on the same thread here
      ms.push_back(std::chrono::duration<double, std::milli>(t1 - t0).count());
      fusion_ms.push_back(std::chrono::duration<double, std::milli>(Clock::now() - t1).count());
    }
    auto stats = [](const std::vector<double>& v) {
      const so::TimeStatistics t = so::TimeStatistics::of(v);
      std::ostringstream s;
      s << std::fixed << std::setprecision(2) << t.mean_ms << " | " << t.median_ms << " | " << t.p99_ms << " | "
        << t.max_ms;
      return s.str();
    };
    std::cout << "| " << so::toString(algorithm) << (mapper ? ", surface (the mapper's default)" : "") << " | "
              << stats(ms) << " | " << stats(fusion_ms) << " |" << std::endl;
  }
  return 0;
}

/// The whole path as the nodelets run it, image in to map fused
/// (WholePath), stage by stage (stage_times.h), frame @p frames[k] of
/// @p scenario for each k. The messages are made beforehand (a camera
/// driver's work). With @p blank every pixel is without a match: what
/// the path costs an image that draws nothing.
int wholePath(const so::FlightScenario& scenario, const std::vector<size_t>& frames, const std::string& title,
              int threads, long pace_ms, bool blank) {
  so::tools::WholePath path(threads);
  std::vector<stereo_msgs::DisparityImageConstPtr> images;
  std::map<size_t, cv::Mat> rendered;  // a frame repeated is rendered once
  for (size_t k = 0; k < frames.size(); ++k) {
    cv::Mat& disparity = rendered[frames[k]];
    if (disparity.empty()) {
      disparity = so::renderStereoFrame(scenario, frames[k], 1);
      if (blank) disparity.setTo(-1.0f);  // no match (stereo_image_proc's invalid value)
    }
    images.push_back(path.prepare(scenario, frames[k], disparity, k));
  }
  std::vector<std::vector<double>> stage_ms(so::kPathStages);
  std::vector<double> whole_ms, outside_ms;
  size_t fused = 0;
  for (const auto& image : images) {
    if (pace_ms > 0) std::this_thread::sleep_for(std::chrono::milliseconds(pace_ms));
    so::StageTimes times;
    const auto t0 = Clock::now();
    fused += path.run(image, &times);
    const double whole = std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
    whole_ms.push_back(whole);
    outside_ms.push_back(whole - times.total());
    for (size_t s = 0; s < so::kPathStages; ++s) stage_ms[s].push_back(times.ms[s]);
  }
  const so::TimeStatistics whole = so::TimeStatistics::of(whole_ms);
  std::cout << title << ": the whole path as the nodelets run it (FrameMapping, MapFusion; the defaults: "
            << so::toString(path.mapper().drawing.algorithm) << ", " << path.mapper().drawing.resolution_m
            << " m cells), " << threadsText(threads)
            << (pace_ms > 0 ? "; a pause of " + std::to_string(pace_ms) + " ms before each frame" : std::string())
            << (blank ? "; every pixel without a match" : "") << "; " << fused << " of " << images.size()
            << " images fused. Per frame [ms]; share: of the mean whole path.\n\n"
               "| stage | mean | median | p99 | max | share |\n|---|---:|---:|---:|---:|---:|\n";
  auto row = [&](const std::string& name, const std::vector<double>& ms) {
    const so::TimeStatistics t = so::TimeStatistics::of(ms);
    std::cout << std::fixed << std::setprecision(3) << "| " << name << " | " << t.mean_ms << " | " << t.median_ms
              << " | " << t.p99_ms << " | " << t.max_ms << " | " << std::setprecision(1)
              << 100.0 * t.mean_ms / whole.mean_ms << " % |\n";
  };
  for (size_t s = 0; s < so::kPathStages; ++s) row(so::toString(static_cast<so::PathStage>(s)), stage_ms[s]);
  row("outside the stages", outside_ms);
  row("**whole path**", whole_ms);
  std::cout << std::endl;
  return fused == images.size() ? 0 : 1;
}

/// One pass of the whole path over a flight's images on a fresh pipeline.
struct PathPass {
  std::vector<double> whole_ms;  ///< per frame
  so::StageTimes stages;         ///< summed over the frames
  size_t fused = 0;              ///< images fused
  std::string map_bytes;         ///< the map at the end, as .ot data (OcTree::writeData)
};

/// WholePath on @p threads threads over @p disparities (frame k of
/// @p scenario each), the messages made first as in wholePath().
PathPass wholePathPass(const so::FlightScenario& scenario, const std::vector<cv::Mat>& disparities, int threads) {
  so::tools::WholePath path(threads);
  std::vector<stereo_msgs::DisparityImageConstPtr> images;
  for (size_t k = 0; k < disparities.size(); ++k) images.push_back(path.prepare(scenario, k, disparities[k], k));
  PathPass pass;
  for (const auto& image : images) {
    const auto t0 = Clock::now();
    pass.fused += path.run(image, &pass.stages);
    pass.whole_ms.push_back(std::chrono::duration<double, std::milli>(Clock::now() - t0).count());
  }
  std::ostringstream data;
  path.fusion().map().tree().writeData(data);
  pass.map_bytes = data.str();
  return pass;
}

/// The median of @p values (the upper one of an even count).
double medianOf(std::vector<double> values) {
  std::sort(values.begin(), values.end());
  return values[values.size() / 2];
}

/// "median× (min-max)" of @p ratios.
std::string ratioRange(const std::vector<double>& ratios) {
  const auto [lo, hi] = std::minmax_element(ratios.begin(), ratios.end());
  std::ostringstream text;
  text << std::fixed << std::setprecision(2) << medianOf(ratios) << "x (" << *lo << "-" << *hi << ")";
  return text.str();
}

/// Issue 48's two threads against one, with this machine's own ceiling in
/// the same minutes: @p rounds rounds of the whole path over flight
/// @p flight on one thread, on two, and two one-thread passes at once (two
/// copies of the same work, one per core). A noisy VM's speed drifts
/// between runs; within a round the three are seconds apart.
int threadRounds(const std::string& flight, int rounds) {
  const so::FlightScenario scenario = so::tools::scenarioNamed(flight);
  std::vector<cv::Mat> disparities;
  for (size_t k = 0; k < scenario.T_W_B.size(); ++k) disparities.push_back(so::renderStereoFrame(scenario, k, 1));
  std::cout << "Flight '" << flight << "', " << disparities.size()
            << " frames: the whole path as the nodelets run it (FrameMapping, MapFusion, the defaults), each pass "
               "into a new map; per round one thread, two threads, then two one-thread passes at once. Mean per "
               "frame [ms]. Ceiling: what two cores give over one on two copies of the same work, 2 x one ÷ a "
               "copy's.\n\n"
               "| round | one thread | two threads | two ÷ one | a copy, two at once | ceiling |\n"
               "|---:|---:|---:|---:|---:|---:|\n";
  std::vector<double> speedups, ceilings, one_means, two_means, copy_means;
  std::vector<so::StageTimes> one_stages, two_stages;  // per round, mean per frame
  bool same_maps = true, all_fused = true;
  for (int r = 0; r < rounds; ++r) {
    const PathPass one = wholePathPass(scenario, disparities, 1);
    const PathPass two = wholePathPass(scenario, disparities, 2);
    PathPass copy_a, copy_b;
    std::thread other([&] { copy_b = wholePathPass(scenario, disparities, 1); });
    copy_a = wholePathPass(scenario, disparities, 1);
    other.join();
    const double one_ms = so::TimeStatistics::of(one.whole_ms).mean_ms;
    const double two_ms = so::TimeStatistics::of(two.whole_ms).mean_ms;
    const double copy_ms =
        0.5 * (so::TimeStatistics::of(copy_a.whole_ms).mean_ms + so::TimeStatistics::of(copy_b.whole_ms).mean_ms);
    auto perFrame = [&](so::StageTimes t) {
      for (double& ms : t.ms) ms /= static_cast<double>(disparities.size());
      return t;
    };
    one_stages.push_back(perFrame(one.stages));
    two_stages.push_back(perFrame(two.stages));
    one_means.push_back(one_ms);
    two_means.push_back(two_ms);
    copy_means.push_back(copy_ms);
    speedups.push_back(one_ms / two_ms);
    ceilings.push_back(2.0 * one_ms / copy_ms);
    same_maps = same_maps && two.map_bytes == one.map_bytes && copy_a.map_bytes == one.map_bytes &&
                copy_b.map_bytes == one.map_bytes;
    for (const PathPass* pass :
         {&one, &two, static_cast<const PathPass*>(&copy_a), static_cast<const PathPass*>(&copy_b)})
      all_fused = all_fused && pass->fused == disparities.size();
    std::cout << std::fixed << std::setprecision(2) << "| " << r + 1 << " | " << one_ms << " | " << two_ms << " | "
              << speedups.back() << "x | " << copy_ms << " | " << ceilings.back() << "x |" << std::endl;
  }
  const double one_ms = medianOf(one_means), two_ms = medianOf(two_means), copy_ms = medianOf(copy_means);
  std::cout << "\nTwo threads ÷ one, median (min-max) of the rounds: " << ratioRange(speedups)
            << "; the ceiling: " << ratioRange(ceilings) << ".\nThe rounds' medians: one thread "
            << std::setprecision(2) << one_ms << " ms, two threads " << two_ms << " ms (" << one_ms / two_ms
            << "x), a copy two at once " << copy_ms << " ms (ceiling " << 2.0 * one_ms / copy_ms
            << "x).\nThe maps of every pass: " << (same_maps ? "the same .ot bytes" : "DIFFERENT .ot bytes") << "; "
            << (all_fused ? "every image fused" : "an image was NOT fused") << "." << std::endl;
  // Where a round that gained least lost its time, beside the median round.
  std::vector<size_t> order(speedups.size());
  for (size_t r = 0; r < order.size(); ++r) order[r] = r;
  std::sort(order.begin(), order.end(), [&](size_t a, size_t b) { return speedups[a] < speedups[b]; });
  const size_t worst = order.front(), middle = order[order.size() / 2];
  std::cout << "\nStage means [ms], one thread and two, in the round of the least gain (" << worst + 1
            << ") and of the median gain (" << middle + 1
            << "):\n\n| stage | least: one | least: two | median: one | median: two |\n|---|---:|---:|---:|---:|\n";
  const so::StageTimes* columns[] = {&one_stages[worst], &two_stages[worst], &one_stages[middle], &two_stages[middle]};
  const double wholes[] = {one_means[worst], two_means[worst], one_means[middle], two_means[middle]};
  auto row = [&](const std::string& name, const std::function<double(size_t column)>& value) {
    std::cout << std::setprecision(3) << "| " << name;
    for (size_t c = 0; c < 4; ++c) std::cout << " | " << value(c);
    std::cout << " |\n";
  };
  for (size_t s = 0; s < so::kPathStages; ++s)
    row(so::toString(static_cast<so::PathStage>(s)), [&](size_t c) { return columns[c]->ms[s]; });
  row("outside the stages", [&](size_t c) { return wholes[c] - columns[c]->total(); });
  row("**whole path**", [&](size_t c) { return wholes[c]; });
  std::cout << std::flush;
  return same_maps && all_fused ? 0 : 1;
}

const char* kStages =
    "line, line_pyramid, raytrace, raytrace_pyramid, line_pyramid_bounded, raytrace_pyramid_bounded, default, blur, "
    "encode, fusion, octomap";

int run(int argc, char** argv) {
  int repeat = 21;
  std::string only, scenario_name, flight;
  long frame = 0, pace_ms = 0;
  int threads = 1;
  bool spans = true, stages = false, blank = false;
  int thread_rounds = 0;        // --thread-rounds: one thread against two, with the ceiling
  bool record_changes = false;  // the fusion records the cells whose class it changed (the distance field's feed)
  std::map<std::string, double> model_values;  // the default stage's sensor model, by name
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--repeat") {
      repeat = static_cast<int>(so::tools::parseWhole(a, so::tools::nextValue(argc, argv, &i), 1, 100000));
    } else if (a == "--only") {
      only = so::tools::nextValue(argc, argv, &i);
      if (std::string(", ").append(kStages).append(",").find(", " + only + ",") == std::string::npos)
        throw so::tools::UsageError("unknown stage '" + only + "' (one of " + kStages + ")");
    } else if (a == "--scenario") {
      scenario_name = so::tools::nextValue(argc, argv, &i);
    } else if (a == "--flight") {
      flight = so::tools::nextValue(argc, argv, &i);
    } else if (a == "--pace-ms") {
      pace_ms = so::tools::parseWhole(a, so::tools::nextValue(argc, argv, &i), 0, 10000);
    } else if (a == "--threads") {
      threads = static_cast<int>(so::tools::parseWhole(a, so::tools::nextValue(argc, argv, &i), 1, 64));
    } else if (a == "--record-changes") {
      record_changes = true;
    } else if (a == "--no-spans") {
      spans = false;
    } else if (a == "--stages") {
      stages = true;
    } else if (a == "--blank") {
      blank = true;
    } else if (a == "--thread-rounds") {
      thread_rounds = static_cast<int>(so::tools::parseWhole(a, so::tools::nextValue(argc, argv, &i), 1, 1000));
    } else if (a == "--model") {
      so::tools::addNameValue(argc, argv, &i, &model_values);
    } else if (a == "--frame") {
      frame = so::tools::parseWhole(a, so::tools::nextValue(argc, argv, &i), 0, 1000000);
    } else if (a == "--help") {
      std::cout
          << "usage: performance [--repeat N] [--only STAGE] [--scenario NAME [--frame K]] | --flight NAME "
             "[--pace-ms MS]; either with [--threads N]; [--model NAME=VALUE]... [--no-spans] "
             "[--record-changes] | --stages (--scenario NAME [--frame K] | --flight NAME [--pace-ms MS]) [--threads N] "
             "[--blank] "
             "| --stages "
             "--flight NAME --thread-rounds R\n"
             "Times the mapper's stages on the Table I frame (or frame K of a simulated flight, with its "
             "stereo effects, seed 1) at 0.25 m (median and min-max of N runs, default 21) and OctoMap's "
             "insertPointCloud on the same frame.\n"
             "--flight NAME: the core of the mapper's path, and the fusion of its update into the flight's "
             "map, on every frame of a simulated flight, with their mean, median, p99 and maximum; "
             "--pace-ms MS sleeps MS before each frame, as between a camera's images (also with --stages --flight).\n"
             "--threads N: draw, blur and fuse on N threads (default 1).\n"
             "--model NAME=VALUE: a sensor model parameter of the default stage and of the flight's "
             "line_pyramid_bounded row (e.g. gap_guard_cells=1), repeatable.\n"
             "--record-changes: the fusion stages record the cells whose class they change, as for the "
             "distance field (MapAccumulator::recordClassChanges).\n"
             "--no-spans: the default descends into the blocks it draws as spans (the form before them).\n"
             "--stages: the whole path as the nodelets run it (FrameMapping, MapFusion, the defaults), "
             "image in to map fused, stage by stage, on frame K repeated N times or on every frame of the "
             "flight.\n"
             "--blank (with --stages): every pixel of the images without a match: what the path costs an image "
             "that draws nothing.\n"
             "--thread-rounds R (with --stages --flight NAME): R rounds of the whole path over the flight on "
             "one thread, on two, and two one-thread passes at once (the machine's ceiling for two cores), "
             "each into a new map; prints each round's means, two threads ÷ one and the ceiling, whether "
             "every pass made the same map (exit 1 if not), and the stage means of the round that gained least "
             "beside the median round's.\n"
             "STAGE: "
          << kStages << "\n";
      return 0;
    } else {
      throw so::tools::UsageError("unknown option '" + a + "'");
    }
  }
  if (pace_ms > 0 && flight.empty()) throw so::tools::UsageError("--pace-ms needs --flight");
  if (pace_ms > 0 && thread_rounds > 0) throw so::tools::UsageError("--pace-ms does not go with --thread-rounds");
  if (blank && (!stages || thread_rounds > 0))
    throw so::tools::UsageError("--blank needs --stages (without --thread-rounds)");
  if (thread_rounds > 0) {
    if (!stages || flight.empty()) throw so::tools::UsageError("--thread-rounds needs --stages --flight NAME");
    return threadRounds(flight, thread_rounds);
  }
  if (stages) {
    if (flight.empty() == scenario_name.empty())
      throw so::tools::UsageError("--stages needs --scenario NAME or --flight NAME");
    if (!flight.empty()) {
      const so::FlightScenario scenario = so::tools::scenarioNamed(flight);
      std::vector<size_t> frames(scenario.T_W_B.size());
      for (size_t k = 0; k < frames.size(); ++k) frames[k] = k;
      return wholePath(scenario, frames, "Flight '" + flight + "', " + std::to_string(frames.size()) + " frames",
                       threads, pace_ms, blank);
    }
    const so::FlightScenario scenario = so::tools::scenarioNamed(scenario_name);
    if (frame >= static_cast<long>(scenario.T_W_B.size()))
      throw so::tools::UsageError("--frame: the flight has " + std::to_string(scenario.T_W_B.size()) + " frames");
    return wholePath(
        scenario, std::vector<size_t>(static_cast<size_t>(repeat), static_cast<size_t>(frame)),
        "Frame " + std::to_string(frame) + " of flight '" + scenario_name + "', " + std::to_string(repeat) + " times",
        threads, 0, blank);
  }
  {  // a wrong --model before any stage runs
    so::DrawingConfig checked = so::DrawingConfig::mapperDefaults();
    so::tools::applyModelValues(model_values, &checked);
  }
  if (!flight.empty()) return flightPath(flight, pace_ms, threads, spans, model_values);
  const bool quiet = !only.empty();
  auto wanted = [&](const std::string& stage) { return only.empty() || only == stage; };

  so::StereoCameraConfig camera;  // the paper's camera
  Eigen::Isometry3d T_W_C;
  cv::Mat image;
  std::string frame_name = "Table I frame";
  if (scenario_name.empty()) {
    image = so::table1Image(so::StereoCameraModel(camera), &T_W_C);
  } else {
    const so::FlightScenario scenario = so::tools::scenarioNamed(scenario_name);
    if (frame >= static_cast<long>(scenario.T_W_B.size()))
      throw so::tools::UsageError("--frame: the flight has " + std::to_string(scenario.T_W_B.size()) + " frames");
    camera = scenario.camera;
    T_W_C = scenario.cameraPose(static_cast<size_t>(frame));
    image = so::renderStereoFrame(scenario, static_cast<size_t>(frame), 1);
    frame_name = "Frame " + std::to_string(frame) + " of flight '" + scenario_name + "'";
  }
  const double resolution = 0.25;
  if (!quiet)
    std::cout << frame_name << ": 640x480, b = 0.3 m, f = 700 px, 25 m range, " << resolution << " m cells; "
              << threadsText(threads) << "; median (min-max) of " << repeat << " runs [ms].\n\n"
              << "| stage | time ms | what is timed |\n|---|---:|---|\n";
  auto row = [&](const std::string& stage, const Timing& t, const std::string& what) {
    if (!quiet) std::cout << "| " << stage << " | " << t.text() << " | " << what << " |" << std::endl;
  };

  // Drawing: pyramids + drawing, into a grid shaped and cleared beforehand.
  double line_pyramid_ms = 0.0;
  for (so::DrawingAlgorithm algorithm : so::allDrawingAlgorithms()) {
    const std::string name = so::toString(algorithm);
    if (!wanted(name)) continue;
    so::DisparityDrawer drawer(camera, so::tools::drawingConfig(algorithm, resolution, threads));
    so::LocalGrid grid;
    const bool slow = algorithm == so::DrawingAlgorithm::kLine || algorithm == so::DrawingAlgorithm::kRayTrace;
    const Timing t = timeIt(
        slow && !quiet ? std::max(3, repeat / 7) : repeat, [&] { drawer.prepareGrid(T_W_C, &grid); },
        [&] { drawer.drawInto(image, T_W_C, &grid); });
    if (algorithm == so::DrawingAlgorithm::kLinePyramid) line_pyramid_ms = t.median();
    row(name, t, "pyramids + drawing");
  }
  // The mapper's default as the mapper draws it (the rows above: the sensor
  // model's own default, the paper's profile), against the paper's pyramid.
  if (wanted("default")) {
    so::DrawingConfig config = so::DrawingConfig::mapperDefaults();
    config.resolution_m = resolution;
    config.threads = threads;
    config.surface_spans = spans;
    so::tools::applyModelValues(model_values, &config);
    so::DisparityDrawer drawer(camera, config);
    so::LocalGrid grid;
    const Timing t = timeIt(
        repeat, [&] { drawer.prepareGrid(T_W_C, &grid); }, [&] { drawer.drawInto(image, T_W_C, &grid); });
    std::ostringstream what;
    what << "pyramids + drawing + the surface guards, " << so::toString(config.algorithm)
         << " with the surface profile";
    if (line_pyramid_ms > 0.0) what << "; " << std::setprecision(3) << t.median() / line_pyramid_ms << "x line_pyramid";
    row("default", t, what.str());
  }

  if (!(only.empty() || only == "blur" || only == "encode" || only == "fusion" || only == "octomap")) return 0;
  // The grid the later stages start from: line_pyramid's, as the mapper's.
  so::DrawingConfig config = so::tools::drawingConfig(so::DrawingAlgorithm::kLinePyramid, resolution, threads);
  config.blur.sigma_trans_m = 0.1;
  config.blur.sigma_angle_rad = 0.01;
  so::DisparityDrawer drawer(camera, config);
  so::LocalGrid drawn;
  drawer.prepareGrid(T_W_C, &drawn);  // padded for the blur
  drawer.drawInto(image, T_W_C, &drawn);
  if (only.empty()) {
    so::LocalGrid grid;
    row("grid preparation",
        timeIt(
            repeat, [] {}, [&] { drawer.prepareGrid(T_W_C, &grid); }),
        "shape the frustum's box (padded for the blur) and set it unknown; " + std::to_string(drawn.numCells()) +
            " cells");
  }

  so::LocalGrid blurred = drawn;
  double blur_ms = 0.0;
  if (wanted("blur")) {
    so::LocalGrid grid;
    const Timing t = timeIt(
        repeat, [&] { grid = drawn; }, [&] { drawer.blur(T_W_C, &grid); });
    blur_ms = t.median();
    blurred = grid;
    row("blur", t, "eq. 17 with σ_trans 0.1 m, σ_angle 0.01 rad over the padded grid");
  } else {
    drawer.blur(T_W_C, &blurred);
  }

  so::GridUpdate update;
  double encode_ms = 0.0;
  if (wanted("encode")) {
    const Timing t = timeIt(
        repeat, [] {}, [&] { so::encodeGridUpdate(blurred, T_W_C.translation(), &update); });
    encode_ms = t.median();
    row("encode", t,
        "known cells of the blurred grid into an update (" + std::to_string(update.numCells()) + " cells)");
  } else {
    so::encodeGridUpdate(blurred, T_W_C.translation(), &update);
  }

  so::MapAccumulatorConfig map_config;
  map_config.resolution_m = resolution;
  map_config.threads = threads;
  double fusion_ms = 0.0;
  if (wanted("fusion")) {
    std::unique_ptr<so::MapAccumulator> map;
    const Timing cold = timeIt(
        repeat,
        [&] {
          map = std::make_unique<so::MapAccumulator>(map_config);
          recordChanges(map.get(), record_changes);
        },
        // Written back at once: one frame alone gains nothing from the cache (a flight does: --stages).
        [&] {
          map->integrate(update);
          map->leafTree();
        });
    row("fusion, new map", cold, "the update into an empty OcTree, written back");
    const Timing warm = timeIt(
        repeat,
        [&] {
          map = std::make_unique<so::MapAccumulator>(map_config);
          recordChanges(map.get(), record_changes);
          map->integrate(update);
          map->leafTree();
        },
        [&] {
          map->integrate(update);
          map->leafTree();
        });
    fusion_ms = warm.median();
    row("fusion", warm, "the update into an OcTree that holds it already (its nodes exist), written back");
  }

  if (wanted("octomap")) {
    const octomap::Pointcloud cloud = so::tools::disparityCloud(image, camera, T_W_C);
    const Eigen::Vector3d o = T_W_C.translation();
    std::unique_ptr<octomap::OcTree> tree;
    const Timing t = timeIt(
        std::max(3, repeat / 7), [&] { tree = std::make_unique<octomap::OcTree>(resolution); },
        [&] {
          tree->insertPointCloud(cloud, octomap::point3d(o.x(), o.y(), o.z()), camera.max_range_m,
                                 /*lazy_eval=*/false, /*discretize=*/true);
        });
    row("OctoMap insertPointCloud", t,
        "discretize on, " + std::to_string(cloud.size()) + " points, into an empty OcTree");
    if (!quiet && line_pyramid_ms > 0.0 && fusion_ms > 0.0) {
      const double ours = line_pyramid_ms + encode_ms + fusion_ms;
      std::cout << "\nOctoMap insertPointCloud / line_pyramid drawing: " << std::fixed << std::setprecision(0)
                << t.median() / line_pyramid_ms << "x; / (line_pyramid + encode + fusion): " << t.median() / ours
                << "x; / (line_pyramid + blur + encode + fusion): " << t.median() / (ours + blur_ms) << "x\n";
    }
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return so::tools::runTool("performance", [&] { return run(argc, argv); });
}
