// One source for each parameter: the table (forEachParameter() of each
// config struct) is what isValid() checks, and config/mapping.yaml,
// config/DisparityMapper.cfg and the README's parameter tables say the same
// names, defaults, units and ranges.

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "stereo_occupancy/DisparityMapperConfig.h"
#include "stereo_occupancy/ros/parameters.h"

using namespace stereo_occupancy;

namespace {

/// One row of a nodelet's table, with its default.
struct Row {
  ParameterSpec spec;
  bool is_number = false;
  bool is_integer = false;
  double number = 0.0;  ///< the default, for numbers
  std::string text;     ///< the default, for the rest (choices by name, flags as true/false)
};

struct Collect {
  std::map<std::string, Row>* rows;
  template <typename T>
  void operator()(const ParameterSpec& spec, const T& value) {
    Row row{spec};
    if constexpr (kIsNumberParameter<T>) {
      row.is_number = true;
      row.is_integer = std::is_integral_v<T>;
      row.number = static_cast<double>(value);
    } else if constexpr (std::is_same_v<T, bool>) {
      row.text = value ? "true" : "false";
    } else if constexpr (std::is_same_v<T, std::string>) {
      row.text = value;
    } else {
      row.text = toString(value);  // a choice
    }
    EXPECT_TRUE(rows->emplace(spec.name, row).second) << spec.name << " is listed twice";
  }
};

template <typename Params>
std::map<std::string, Row> tableOf() {
  std::map<std::string, Row> rows;
  const Params defaults;
  Params::forEachParameter(defaults, Collect{&rows});
  return rows;
}

std::string readFile(const std::string& path) {
  std::ifstream in(path);
  EXPECT_TRUE(in.good()) << path;
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

std::string trim(const std::string& s) {
  const size_t a = s.find_first_not_of(" \t"), b = s.find_last_not_of(" \t");
  return a == std::string::npos ? "" : s.substr(a, b - a + 1);
}

bool parseNumber(const std::string& s, double* v) {
  char* end = nullptr;
  *v = std::strtod(s.c_str(), &end);
  return !s.empty() && *end == '\0';
}

/// Sets @p field of @p params to @p value and says whether isValid() objects
/// to this field's range (other checks may fail; they do not count).
template <typename Params>
bool rangeRefuses(const std::string& field, double value, std::string* why) {
  Params params;
  Params::forEachParameter(params, [&](const ParameterSpec& spec, auto& member) {
    using T = std::decay_t<decltype(member)>;
    if constexpr (kIsNumberParameter<T>)
      if (field == spec.name) member = static_cast<T>(value);
  });
  why->clear();
  return !params.isValid(why) && why->rfind(field + " must be in", 0) == 0;
}

template <typename Params>
void expectIsValidChecksTheTable() {
  for (const auto& [name, row] : tableOf<Params>()) {
    if (!row.is_number) continue;
    std::string why;
    EXPECT_FALSE(rangeRefuses<Params>(name, row.spec.min, &why)) << name << " at its minimum: " << why;
    EXPECT_FALSE(rangeRefuses<Params>(name, row.spec.max, &why)) << name << " at its maximum: " << why;
    EXPECT_FALSE(rangeRefuses<Params>(name, row.number, &why)) << name << " at its default: " << why;
    const double step = row.is_integer ? 1.0 : std::max(1.0, std::abs(row.spec.max)) * 1e-6;
    EXPECT_TRUE(rangeRefuses<Params>(name, row.spec.min - step, &why)) << name << " below its minimum";
    if (row.spec.max < std::numeric_limits<int>::max())  // an int's limit cannot be passed
      EXPECT_TRUE(rangeRefuses<Params>(name, row.spec.max + step, &why)) << name << " above its maximum";
  }
}

/// The `key: value  # comment` lines of one section of config/mapping.yaml.
std::map<std::string, std::pair<std::string, std::string>> yamlSection(const std::string& section) {
  std::map<std::string, std::pair<std::string, std::string>> entries;
  std::istringstream in(readFile(std::string(SOURCE_DIR) + "/config/mapping.yaml"));
  std::string line;
  bool inside = false;
  while (std::getline(in, line)) {
    if (!line.empty() && line[0] != ' ' && line[0] != '#') inside = line == section + ":";
    if (!inside || line.rfind("  ", 0) != 0 || trim(line).empty() || trim(line)[0] == '#') continue;
    const size_t colon = line.find(':'), hash = line.find('#');
    const std::string value =
        trim(line.substr(colon + 1, hash == std::string::npos ? std::string::npos : hash - colon - 1));
    entries[trim(line.substr(0, colon))] = {value, hash == std::string::npos ? "" : line.substr(hash + 1)};
  }
  return entries;
}

template <typename Params>
void expectYamlSaysTheTable(const std::string& section) {
  const auto rows = tableOf<Params>();
  const auto yaml = yamlSection(section);
  for (const auto& [name, row] : rows) {
    const auto it = yaml.find(name);
    if (it == yaml.end()) {
      ADD_FAILURE() << section << "." << name << " is missing from config/mapping.yaml";
      continue;
    }
    const auto& [value, comment] = it->second;
    if (row.is_number) {
      double v;
      EXPECT_TRUE(parseNumber(value, &v) && v == row.number) << section << "." << name << ": " << value;
      EXPECT_NE(comment.find(row.spec.rangeText()), std::string::npos)
          << section << "." << name << ": the comment should give the range " << row.spec.rangeText();
    } else {
      EXPECT_EQ(value == "\"\"" ? "" : value, row.text) << section << "." << name;
    }
  }
  for (const auto& entry : yaml)
    EXPECT_TRUE(rows.count(entry.first)) << section << "." << entry.first << " is no parameter";
}

/// The rows `| \`name\` | type | default | range | unit | meaning |` of the
/// README's section about @p nodelet, by name.
std::map<std::string, std::vector<std::string>> readmeRows(const std::string& nodelet) {
  std::map<std::string, std::vector<std::string>> rows;
  std::istringstream in(readFile(std::string(SOURCE_DIR) + "/README.md"));
  std::string line;
  bool inside = false;
  while (std::getline(in, line)) {
    if (line.rfind("## ", 0) == 0 || line.rfind("### ", 0) == 0)
      inside = line == "### `stereo_occupancy/" + nodelet + "`";
    if (!inside || line.rfind("| `", 0) != 0) continue;
    std::vector<std::string> cells;
    std::stringstream cut(line.substr(1));
    for (std::string cell; std::getline(cut, cell, '|');) cells.push_back(trim(cell));
    if (cells.size() < 6) continue;  // another table (topics, services)
    std::stringstream names(cells[0]);
    for (std::string name; std::getline(names, name, ',');) {
      name = trim(name);
      rows[name.substr(1, name.size() - 2)] = cells;  // without the backticks
    }
  }
  return rows;
}

template <typename Params>
void expectReadmeSaysTheTable(const std::string& nodelet) {
  const auto rows = tableOf<Params>();
  const auto readme = readmeRows(nodelet);
  for (const auto& [name, row] : rows) {
    const auto it = readme.find(name);
    if (it == readme.end()) {
      ADD_FAILURE() << nodelet << ": " << name << " is missing from the README's parameter table";
      continue;
    }
    const std::vector<std::string>& cells = it->second;  // name, type, default, range, unit, meaning
    if (row.is_number) {
      double v;
      EXPECT_TRUE(parseNumber(cells[2], &v) && v == row.number) << nodelet << ": " << name << " default " << cells[2];
      EXPECT_EQ(cells[3], row.spec.rangeText()) << nodelet << ": " << name;
      EXPECT_EQ(cells[4], row.spec.unit) << nodelet << ": " << name;
    } else {
      std::string shown = cells[2];
      if (shown.size() >= 2 && shown.front() == '`' && shown.back() == '`') shown = shown.substr(1, shown.size() - 2);
      EXPECT_EQ(shown == "\"\"" ? "" : shown, row.text) << nodelet << ": " << name;
    }
  }
  for (const auto& entry : readme)
    EXPECT_TRUE(rows.count(entry.first)) << nodelet << ": " << entry.first << " is no parameter";
}

}  // namespace

TEST(ParameterTable, IsValidChecksTheTablesRanges) {
  expectIsValidChecksTheTable<DisparityMapperParameters>();
  expectIsValidChecksTheTable<OctomapAccumulatorParameters>();
  expectIsValidChecksTheTable<PathWatcherParameters>();
  std::string why;
  DisparityMapperParameters nan;
  nan.drawing.sensor_model.k_m = std::nan("");
  EXPECT_FALSE(nan.isValid(&why));
  EXPECT_EQ(why.rfind("k_m must be in [0.001, 10]", 0), 0u) << why;
}

TEST(ParameterTable, TheCfgHasTheTablesDefaultsAndRanges) {
  const auto rows = tableOf<DisparityMapperParameters>();
  dynamic_reconfigure::Config min, max, defaults;
  DisparityMapperConfig::__getMin__().__toMessage__(min);
  DisparityMapperConfig::__getMax__().__toMessage__(max);
  DisparityMapperConfig::__getDefault__().__toMessage__(defaults);
  ASSERT_FALSE(defaults.doubles.empty());
  ASSERT_FALSE(defaults.ints.empty());
  for (size_t i = 0; i < defaults.doubles.size(); ++i) {
    const std::string& name = defaults.doubles[i].name;
    const auto it = rows.find(name);
    ASSERT_NE(it, rows.end()) << name << " of the .cfg is not in the table";
    EXPECT_TRUE(it->second.is_number && !it->second.is_integer) << name << " is a double in the .cfg only";
    EXPECT_EQ(defaults.doubles[i].value, it->second.number) << name;
    EXPECT_EQ(min.doubles[i].value, it->second.spec.min) << name;
    EXPECT_EQ(max.doubles[i].value, it->second.spec.max) << name;
  }
  for (size_t i = 0; i < defaults.ints.size(); ++i) {
    const std::string& name = defaults.ints[i].name;
    const auto it = rows.find(name);
    ASSERT_NE(it, rows.end()) << name << " of the .cfg is not in the table";
    EXPECT_TRUE(it->second.is_integer) << name << " is an int in the .cfg only";
    EXPECT_EQ(defaults.ints[i].value, it->second.number) << name;
    EXPECT_EQ(min.ints[i].value, it->second.spec.min) << name;
    EXPECT_EQ(max.ints[i].value, it->second.spec.max) << name;
  }
  for (const auto& entry : defaults.bools) {
    const auto it = rows.find(entry.name);
    ASSERT_NE(it, rows.end()) << entry.name << " of the .cfg is not in the table";
    EXPECT_EQ(entry.value ? "true" : "false", it->second.text) << entry.name;
  }
  for (const auto& entry : defaults.strs) {
    const auto it = rows.find(entry.name);
    ASSERT_NE(it, rows.end()) << entry.name << " of the .cfg is not in the table";
    EXPECT_FALSE(it->second.is_number) << entry.name << " is a string in the .cfg only";
    EXPECT_EQ(entry.value, it->second.text) << entry.name;
  }
  // Every parameter of the .cfg was one of those compared.
  EXPECT_EQ(defaults.doubles.size() + defaults.ints.size() + defaults.bools.size() + defaults.strs.size(),
            DisparityMapperConfig::__getParamDescriptions__().size());
  // The server shows the values in use: the table's names map them both ways.
  DisparityMapperParameters params;
  params.drawing.sensor_model.k_m = 0.25;
  params.drawing.algorithm = DrawingAlgorithm::kRayTrace;
  std::set<std::string> names;
  for (const auto& d : DisparityMapperConfig::__getParamDescriptions__()) names.insert(d->name);
  dynamic_reconfigure::Config msg;
  toReconfigureMessage(params, names, &msg);
  DisparityMapperConfig config;
  ASSERT_TRUE(config.__fromMessage__(msg));
  EXPECT_EQ(config.k_m, 0.25);
  EXPECT_EQ(config.algorithm, "raytrace");
  config.max_range_m = 40.0;
  config.__toMessage__(msg);
  std::string why;
  ASSERT_TRUE(fromReconfigureMessage(msg, &params, &why)) << why;
  EXPECT_EQ(params.camera.max_range_m, 40.0);
  config.min_range_m = 50.0;  // within its range, but beyond max_range_m: refused, params unchanged
  config.__toMessage__(msg);
  EXPECT_FALSE(fromReconfigureMessage(msg, &params, &why));
  EXPECT_EQ(params.camera.min_range_m, 0.5);
}

TEST(ParameterTable, MappingYamlSaysTheTable) {
  expectYamlSaysTheTable<DisparityMapperParameters>("disparity_mapper");
  expectYamlSaysTheTable<OctomapAccumulatorParameters>("octomap_accumulator");
}

TEST(ParameterTable, TheReadmeTablesSayTheTable) {
  expectReadmeSaysTheTable<DisparityMapperParameters>("DisparityMapper");
  expectReadmeSaysTheTable<OctomapAccumulatorParameters>("OctomapAccumulator");
  expectReadmeSaysTheTable<PathWatcherParameters>("PathWatcher");
}

namespace {

/// What `roslaunch --dump-params` gives for mapping.launch with @p args: name -> value text.
std::map<std::string, std::string> launchParams(const std::string& args) {
  std::map<std::string, std::string> params;
  const std::string command = "roslaunch --dump-params stereo_occupancy mapping.launch " + args + " 2>&1";
  FILE* pipe = popen(command.c_str(), "r");
  if (!pipe) return params;
  char line[4096];
  while (fgets(line, sizeof line, pipe)) {
    const std::string text(line);
    const size_t colon = text.find(": ");
    if (text.rfind('/', 0) != 0 || colon == std::string::npos) continue;
    std::string value = text.substr(colon + 2);
    while (!value.empty() && (value.back() == '\n' || value.back() == '\r')) value.pop_back();
    params[text.substr(0, colon)] = value;
  }
  pclose(pipe);
  return params;
}

}  // namespace

// mapping.launch's world_frame, save_dir and map_file args overwrote the
// same entries of the user's YAML with their defaults, silently: not given,
// they leave the config's values; given, they win.
TEST(LaunchFile, ArgsNotGivenLeaveTheConfigsValues) {
  std::string yaml = readFile(std::string(SOURCE_DIR) + "/config/mapping.yaml");
  for (const auto& [from, to] :
       {std::make_pair(std::string("world_frame: map "), std::string("world_frame: odom ")),
        std::make_pair(std::string("save_dir: \"\""), std::string("save_dir: /tmp/my_maps")),
        std::make_pair(std::string("map_file: \"\""), std::string("map_file: /tmp/my_map.ot"))}) {
    size_t at = 0, replaced = 0;
    while ((at = yaml.find(from, at)) != std::string::npos) yaml.replace(at, from.size(), to), ++replaced;
    ASSERT_GT(replaced, 0u) << "config/mapping.yaml has no '" << from << "'";
  }
  const std::string config = ::testing::TempDir() + "/my_mapping.yaml";
  std::ofstream(config) << yaml;
  const auto own = launchParams("config:=" + config);
  ASSERT_FALSE(own.empty()) << "roslaunch --dump-params gave nothing (is the workspace sourced?)";
  EXPECT_EQ(own.at("/disparity_mapper/world_frame"), "odom");
  EXPECT_EQ(own.at("/octomap_accumulator/world_frame"), "odom");
  EXPECT_EQ(own.at("/octomap_accumulator/save_dir"), "/tmp/my_maps");
  EXPECT_EQ(own.at("/octomap_accumulator/map_file"), "/tmp/my_map.ot");
  const auto given = launchParams("config:=" + config + " world_frame:=map save_dir:=/tmp/other");
  EXPECT_EQ(given.at("/disparity_mapper/world_frame"), "map");
  EXPECT_EQ(given.at("/octomap_accumulator/world_frame"), "map");
  EXPECT_EQ(given.at("/octomap_accumulator/save_dir"), "/tmp/other");
  EXPECT_EQ(given.at("/octomap_accumulator/map_file"), "/tmp/my_map.ot");
}

TEST(Parameters, DefaultsAreValidAndBadValuesNameTheParameter) {
  DisparityMapperParameters mapper;
  std::string why;
  EXPECT_TRUE(mapper.isValid(&why)) << why;
  mapper.camera.max_range_m = -1.0;
  EXPECT_FALSE(mapper.isValid(&why));
  EXPECT_NE(why.find("max_range_m"), std::string::npos) << why;
  mapper = DisparityMapperParameters();
  mapper.drawing.sensor_model.p_min = 0.7;
  EXPECT_FALSE(mapper.isValid(&why));
  EXPECT_NE(why.find("p_min"), std::string::npos) << why;
  OctomapAccumulatorParameters acc;
  EXPECT_TRUE(acc.isValid(&why)) << why;
  for (const char* escaping : {"../escape", "..", ".", "", ".hidden", "a b", "map\n"}) {
    acc.saving.map_name = escaping;
    EXPECT_FALSE(acc.isValid(&why)) << "'" << escaping << "'";
    EXPECT_NE(why.find("map_name"), std::string::npos);
  }
  for (const char* plain : {"flight_2026-12-01", "map.v2", "M"}) {
    acc.saving.map_name = plain;
    EXPECT_TRUE(acc.isValid(&why)) << plain << ": " << why;
  }
  acc = OctomapAccumulatorParameters();
  acc.map.max_update_cells = 0;
  EXPECT_FALSE(acc.isValid(&why));
  EXPECT_NE(why.find("max_update_cells"), std::string::npos) << why;
}

TEST(Parameters, FromNameValuePairs) {
  DisparityMapperParameters mapper;
  OctomapAccumulatorParameters accumulator;
  std::string why;
  ASSERT_TRUE(loadParameters({{"algorithm", "raytrace"},
                              {"resolution_m", "0.5"},
                              {"use_depth", "true"},
                              {"queue_size", "7"},
                              {"map_name", "flight"}},
                             &mapper, &accumulator, &why))
      << why;
  EXPECT_EQ(mapper.drawing.algorithm, DrawingAlgorithm::kRayTrace);
  EXPECT_DOUBLE_EQ(mapper.drawing.resolution_m, 0.5);
  EXPECT_DOUBLE_EQ(accumulator.map.resolution_m, 0.5);  // a name both have sets both
  EXPECT_TRUE(mapper.use_depth);
  EXPECT_EQ(mapper.queue_size, 7);
  EXPECT_EQ(accumulator.saving.map_name, "flight");
  mapper = DisparityMapperParameters();
  EXPECT_FALSE(loadParameters({{"resolution", "0.5"}}, &mapper, &accumulator, &why));
  EXPECT_NE(why.find("unknown parameter 'resolution'"), std::string::npos) << why;
  EXPECT_FALSE(loadParameters({{"queue_size", "many"}}, &mapper, &accumulator, &why));
  EXPECT_NE(why.find("queue_size"), std::string::npos) << why;
  EXPECT_EQ(mapper.queue_size, 5);  // unchanged by the unreadable value
  EXPECT_FALSE(loadParameters({{"p_min", "0.8"}}, &mapper, &accumulator, &why));
  EXPECT_NE(why.find("p_min"), std::string::npos) << why;
}
