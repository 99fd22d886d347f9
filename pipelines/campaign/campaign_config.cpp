#include "demcal/pipelines/archive.hpp"
#include "demcal/pipelines/campaign.hpp"

#include "demcal/common/format.hpp"
#include "demcal/dem/generators.hpp"
#include "demcal/limits/limits.hpp"

#include <cmath>
#include <type_traits>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>

namespace demcal::pipelines {

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

std::string describe(const json& value) {
  std::string text = value.dump();
  return text.size() > 60 ? text.substr(0, 60) + "..." : text;
}

// What a field of type T holds, for messages.
template <class T>
const char* expected_kind() {
  if constexpr (std::is_same_v<T, bool>) return "true or false";
  else if constexpr (std::is_integral_v<T>) return "an integer";
  else if constexpr (std::is_floating_point_v<T>) return "a number";
  else if constexpr (std::is_same_v<T, std::string>) return "a string";
  else return "a value of another type";
}

// Reads j[key] into out if present, with a message naming where/key and the value on a type error.
template <class T>
void read_field(const json& j, const char* key, T& out, const std::string& where) {
  if (!j.contains(key)) return;
  try {
    out = j.at(key).get<T>();
  } catch (const std::exception&) {
    throw CampaignError(where + "." + key + ": expected " + expected_kind<T>() + ", got " + describe(j.at(key)));
  }
  if constexpr (std::is_floating_point_v<T>) {
    if (!std::isfinite(out)) throw CampaignError(where + "." + key + ": value must be finite, got " + describe(j.at(key)));
  }
}

void reject_unknown_keys(const json& j, const std::set<std::string>& known, const std::string& where) {
  if (!j.is_object()) throw CampaignError(where + ": expected a JSON object, got " + describe(j));
  for (const auto& [key, value] : j.items()) {
    if (!known.count(key)) {
      std::string list;
      for (const auto& k : known) list += (list.empty() ? "" : ", ") + k;
      throw CampaignError(where + ": unknown key '" + key + "' (known: " + list + ")");
    }
  }
}

std::string resolve(const std::string& path, const std::string& base_dir) {
  if (path.empty() || fs::path(path).is_absolute() || base_dir.empty()) return path;
  return (fs::path(base_dir) / path).lexically_normal().string();
}

std::string file_hash(const std::string& path) {
  if (auto m = limits::check_file_size(path)) throw CampaignError(path + ": " + *m);
  std::ifstream in(path, std::ios::binary);
  std::ostringstream buffer;
  buffer << in.rdbuf();
  return hash_text(buffer.str());
}

SceneSpec parse_scene(const json& j, const std::string& base_dir, const std::string& where) {
  SceneSpec spec;
  if (j.is_string()) {
    spec.file = resolve(j.get<std::string>(), base_dir);
    return spec;
  }
  reject_unknown_keys(j, {"file", "generator", "options", "solver"}, where);
  read_field(j, "file", spec.file, where);
  read_field(j, "generator", spec.generator, where);
  if (j.contains("options")) spec.options = j.at("options");
  if (j.contains("solver")) {
    spec.solver = j.at("solver");
    reject_unknown_keys(spec.solver,
                        {"local_damping", "time_step_safety", "time_step", "time_step_faces", "density_scaling",
                         "equilibrium_ratio", "max_equilibrium_time", "max_time", "collapse_displacement", "max_velocity"},
                        where + ".solver");
  }
  spec.file = resolve(spec.file, base_dir);
  if (!spec.file.empty() && !spec.generator.empty())
    throw CampaignError(where + ": give either 'file' or 'generator', not both");
  if (!spec.generator.empty() && spec.generator != "arch" && spec.generator != "wall")
    throw CampaignError(where + ".generator: unknown generator '" + spec.generator + "' (known: arch, wall)");
  return spec;
}

MeasuredSpec parse_measured(const json& j, const std::string& base_dir, const std::string& where) {
  MeasuredSpec spec;
  if (j.is_string()) {
    spec.file = resolve(j.get<std::string>(), base_dir);
    return spec;
  }
  reject_unknown_keys(j, {"file", "columns"}, where);
  read_field(j, "file", spec.file, where);
  spec.file = resolve(spec.file, base_dir);
  if (j.contains("columns")) {
    const json& columns = j.at("columns");
    if (!columns.is_object()) throw CampaignError(where + ".columns: expected an object target -> {column, unit}");
    for (const auto& [target, value] : columns.items()) {
      ColumnMapping m;
      m.target = target;
      const std::string at = where + ".columns." + target;
      if (value.is_string()) {
        m.column = value.get<std::string>();
      } else {
        reject_unknown_keys(value, {"column", "unit", "scale"}, at);
        read_field(value, "column", m.column, at);
        read_field(value, "unit", m.unit, at);
        read_field(value, "scale", m.scale, at);
      }
      if (m.column.empty()) throw CampaignError(at + ": missing 'column' (the file's column name)");
      unit_factor(m.unit, at + ".unit");
      spec.columns.push_back(m);
    }
  }
  return spec;
}

void parse_optimiser(const json& j, optimise::OptimiserOptions& o, const std::string& where) {
  reject_unknown_keys(j, {"algorithm", "population", "iterations", "max_evaluations", "seed", "target_value",
                          "inertia_start", "inertia_end", "pso_cognitive", "pso_social", "tbpso_cognitive",
                          "tbpso_social", "tbpso_trust", "constriction", "max_velocity", "initial_velocity",
                          "bounds", "trust_direction", "crossover_probability", "mutation_probability",
                          "ga_mutation", "ga_sigma_start", "ga_sigma_end", "elitism", "initial_step",
                          "nlopt_population", "xtol_rel", "ftol_abs"},
                      where);
  read_field(j, "algorithm", o.algorithm, where);
  read_field(j, "population", o.population, where);
  read_field(j, "iterations", o.iterations, where);
  read_field(j, "max_evaluations", o.max_evaluations, where);
  read_field(j, "seed", o.seed, where);
  read_field(j, "target_value", o.target_value, where);
  read_field(j, "inertia_start", o.inertia_start, where);
  read_field(j, "inertia_end", o.inertia_end, where);
  read_field(j, "pso_cognitive", o.pso_cognitive, where);
  read_field(j, "pso_social", o.pso_social, where);
  read_field(j, "tbpso_cognitive", o.tbpso_cognitive, where);
  read_field(j, "tbpso_social", o.tbpso_social, where);
  read_field(j, "tbpso_trust", o.tbpso_trust, where);
  read_field(j, "constriction", o.constriction, where);
  read_field(j, "max_velocity", o.max_velocity, where);
  read_field(j, "initial_velocity", o.initial_velocity, where);
  read_field(j, "trust_direction", o.trust_direction, where);
  read_field(j, "crossover_probability", o.crossover_probability, where);
  read_field(j, "mutation_probability", o.mutation_probability, where);
  read_field(j, "ga_sigma_start", o.ga_sigma_start, where);
  read_field(j, "ga_sigma_end", o.ga_sigma_end, where);
  read_field(j, "elitism", o.elitism, where);
  read_field(j, "initial_step", o.initial_step, where);
  read_field(j, "nlopt_population", o.nlopt_population, where);
  read_field(j, "xtol_rel", o.xtol_rel, where);
  read_field(j, "ftol_abs", o.ftol_abs, where);
  try {
    if (j.contains("bounds")) o.bounds = optimise::parse_bound_handling(j.at("bounds").get<std::string>());
    if (j.contains("ga_mutation")) o.ga_mutation = optimise::parse_ga_mutation(j.at("ga_mutation").get<std::string>());
  } catch (const std::exception& e) {
    throw CampaignError(where + ": " + e.what());
  }
}

void parse_polish(const json& j, PolishSpec& p, const std::string& where) {
  reject_unknown_keys(j, {"algorithm", "max_evaluations", "initial_step", "xtol_rel"}, where);
  p.enabled = true;
  read_field(j, "algorithm", p.options.algorithm, where);
  read_field(j, "max_evaluations", p.options.max_evaluations, where);
  read_field(j, "initial_step", p.options.initial_step, where);
  read_field(j, "xtol_rel", p.options.xtol_rel, where);
}

json polish_to_json(const PolishSpec& p) {
  return {{"algorithm", p.options.algorithm}, {"max_evaluations", p.options.max_evaluations},
          {"initial_step", p.options.initial_step}, {"xtol_rel", p.options.xtol_rel}};
}

json optimiser_to_json(const optimise::OptimiserOptions& o) {
  return {{"algorithm", o.algorithm},
          {"population", o.population},
          {"iterations", o.iterations},
          {"max_evaluations", o.max_evaluations},
          {"seed", o.seed},
          {"target_value", std::isfinite(o.target_value) ? json(o.target_value) : json(nullptr)},
          {"inertia_start", o.inertia_start},
          {"inertia_end", o.inertia_end},
          {"pso_cognitive", o.pso_cognitive},
          {"pso_social", o.pso_social},
          {"tbpso_cognitive", o.tbpso_cognitive},
          {"tbpso_social", o.tbpso_social},
          {"tbpso_trust", o.tbpso_trust},
          {"constriction", o.constriction},
          {"max_velocity", o.max_velocity},
          {"initial_velocity", o.initial_velocity},
          {"bounds", optimise::to_string(o.bounds)},
          {"trust_direction", o.trust_direction},
          {"crossover_probability", o.crossover_probability},
          {"mutation_probability", o.mutation_probability},
          {"ga_mutation", optimise::to_string(o.ga_mutation)},
          {"ga_sigma_start", o.ga_sigma_start},
          {"ga_sigma_end", o.ga_sigma_end},
          {"elitism", o.elitism},
          {"initial_step", o.initial_step},
          {"nlopt_population", o.nlopt_population},
          {"xtol_rel", o.xtol_rel},
          {"ftol_abs", o.ftol_abs}};
}

void parse_smoother(const json& j, smoothing::SmootherOptions& s, const std::string& where) {
  reject_unknown_keys(j, {"points", "hidden_layers", "hidden_width", "epochs", "learning_rate",
                          "final_learning_rate", "first_layer_gain", "stopping", "check_interval",
                          "trend_cutoff", "backend", "seed", "threads"},
                      where);
  read_field(j, "points", s.points, where);
  read_field(j, "hidden_layers", s.hidden_layers, where);
  read_field(j, "hidden_width", s.hidden_width, where);
  read_field(j, "epochs", s.epochs, where);
  read_field(j, "learning_rate", s.learning_rate, where);
  read_field(j, "final_learning_rate", s.final_learning_rate, where);
  read_field(j, "first_layer_gain", s.first_layer_gain, where);
  read_field(j, "check_interval", s.check_interval, where);
  read_field(j, "trend_cutoff", s.trend_cutoff, where);
  read_field(j, "seed", s.seed, where);
  read_field(j, "threads", s.threads, where);
  std::string text;
  try {
    if (j.contains("stopping")) {
      read_field(j, "stopping", text, where);
      s.stopping = smoothing::parse_stopping_rule(text);
    }
    if (j.contains("backend")) {
      read_field(j, "backend", text, where);
      s.backend = smoothing::parse_smoother_backend(text);
    }
  } catch (const std::invalid_argument& e) {
    throw CampaignError(where + ": " + e.what());
  }
}

// Every option that changes a smoothed curve is here: it is part of the objective key under which
// the archive keeps fitness values, so values of another smoother are never read back.
json smoother_to_json(const smoothing::SmootherOptions& s) {
  return {{"points", s.points}, {"hidden_layers", s.hidden_layers}, {"hidden_width", s.hidden_width},
          {"epochs", s.epochs}, {"learning_rate", s.learning_rate}, {"final_learning_rate", s.final_learning_rate},
          {"first_layer_gain", s.first_layer_gain}, {"stopping", smoothing::to_string(s.stopping)},
          {"check_interval", s.check_interval}, {"trend_cutoff", s.trend_cutoff},
          {"backend", smoothing::to_string(s.backend)}, {"seed", s.seed}, {"threads", s.threads}};
}

json scene_to_json_spec(const SceneSpec& s) {
  json j = json::object();
  if (!s.file.empty()) j["file"] = s.file;
  if (!s.generator.empty()) {
    j["generator"] = s.generator;
    j["options"] = s.options;
  }
  if (!s.solver.empty()) j["solver"] = s.solver;
  return j;
}

json measured_to_json(const MeasuredSpec& m) {
  json columns = json::object();
  for (const auto& c : m.columns) columns[c.target] = {{"column", c.column}, {"unit", c.unit}, {"scale", c.scale}};
  return {{"file", m.file}, {"columns", columns}};
}

// A parameter entry with "log"/"log10"/"linear" scale and lower/upper (min/max accepted).
json normalise_parameter(json p, const std::string& where) {
  if (!p.is_object()) throw CampaignError(where + ": expected {name, lower, upper, scale}, got " + describe(p));
  reject_unknown_keys(p, {"name", "lower", "upper", "min", "max", "scale"}, where);
  if (p.contains("min")) p["lower"] = p["min"], p.erase("min");
  if (p.contains("max")) p["upper"] = p["max"], p.erase("max");
  if (p.contains("scale") && p["scale"].is_string() && p["scale"] == "log") p["scale"] = "log10";
  for (const char* key : {"lower", "upper"}) {
    if (!p.contains(key)) throw CampaignError(where + ": missing '" + key + "'");
    if (!p[key].is_number()) throw CampaignError(where + "." + key + ": not a number: " + describe(p[key]));
  }
  return p;
}

}  // namespace

double unit_factor(const std::string& unit, const std::string& where) {
  static const std::map<std::string, double> factors{
      {"", 1},      {"m", 1},     {"mm", 1e-3}, {"cm", 1e-2}, {"um", 1e-6}, {"µm", 1e-6},
      {"N", 1},     {"kN", 1e3},  {"MN", 1e6},  {"s", 1},     {"-", 1}};
  const auto it = factors.find(unit);
  if (it == factors.end())
    throw CampaignError(where + ": unknown unit '" + unit + "' (known: m, mm, cm, um, N, kN, MN, s)");
  return it->second;
}

std::string surrogate_model_kind(const std::string& path) {
  std::ifstream in(path);
  const json model = json::parse(in, nullptr, false);
  return model.is_object() && model.contains("kind") && model.at("kind").is_string() ? model.at("kind").get<std::string>()
                                                                                        : std::string();
}

void parse_surrogate(const json& j, SurrogateSpec& spec, const std::string& where, const std::string& base_dir) {
  if (!j.is_object()) throw CampaignError(where + ": expected an object");
  json options = j;
  if (options.contains("model")) {
    const json& model = options.at("model");
    if (!model.is_string()) throw CampaignError(where + ".model: expected a file name, got " + model.dump());
    fs::path file = model.get<std::string>();
    if (file.is_relative()) file = fs::path(base_dir) / file;
    spec.model_file = file.string();
    if (auto m = limits::check_file_size(spec.model_file)) throw CampaignError(where + ".model: " + spec.model_file + ": " + *m);
    options.erase("model");
    // Without a "kind", the model's own kind.
    if (const std::string kind = surrogate_model_kind(spec.model_file); !options.contains("kind") && !kind.empty())
      options["kind"] = kind;
  }
  try {
    spec.options = surrogate::SurrogateOptions::from_json(options, where);
  } catch (const std::exception& e) {
    throw CampaignError(e.what());
  }
  spec.enabled = true;
}

json surrogate_to_json(const SurrogateSpec& spec) {
  json j = spec.options.to_json();
  if (!spec.model_file.empty()) {
    j["model"] = spec.model_file;
    j["model_content_hash"] = file_hash(spec.model_file);
  }
  return j;
}

void CampaignConfig::Validate() const {
  // The backend first: whether a case needs a scene depends on it.
  if (backend.type != "threads" && backend.type != "command" && backend.type != "mpi")
    throw CampaignError(source + ": backend.type: unknown backend '" + backend.type + "' (known: threads, command, mpi)");
  if (cases.empty()) throw CampaignError(source + ": no case (give 'scene' and 'measured', or 'cases')");
  std::set<std::string> names;
  for (size_t i = 0; i < cases.size(); ++i) {
    const auto& c = cases[i];
    const std::string where = source + ": cases[" + std::to_string(i) + "]";
    if (!names.insert(c.name).second) throw CampaignError(where + ".name: duplicate case name '" + c.name + "'");
    if (c.measured.file.empty()) throw CampaignError(where + ".measured: no measured file");
    if (!fs::exists(c.measured.file)) throw CampaignError(where + ".measured.file: no such file: " + c.measured.file);
    if (backend.type != "command" && c.scene.file.empty() && c.scene.generator.empty())
      throw CampaignError(where + ".scene: no scene (a 'file' or a 'generator')");
    if (!c.scene.file.empty() && !fs::exists(c.scene.file))
      throw CampaignError(where + ".scene.file: no such file: " + c.scene.file);
    if (!(c.weight >= 0) || !std::isfinite(c.weight))
      throw CampaignError(where + ".weight: must be >= 0, got " + std::to_string(c.weight));
  }
  if (objective != 1 && objective != 2)
    throw CampaignError(source + ": objective.type must be 1 or 2, got " + std::to_string(objective));
  try {
    space.Validate();
  } catch (const std::exception& e) {
    throw CampaignError(source + ": parameters: " + e.what());
  }
  try {
    if (optimiser.algorithm == "bo") {  // the surrogate module's optimiser: the shared options still apply
      optimise::OptimiserOptions shared = optimiser;
      shared.algorithm = "pso";
      shared.Validate();
    } else {
      optimiser.Validate();
    }
    objective_options.Validate();
    smoother.Validate();
  } catch (const std::exception& e) {
    throw CampaignError(source + ": " + e.what());
  }
  if (backend.type == "command" && backend.command.empty())
    throw CampaignError(source + ": backend.command: the command backend needs a command template");
  if (!(backend.timeout_s >= 0))
    throw CampaignError(source + ": backend.timeout_s: must be >= 0, got " + format_number(backend.timeout_s, 6));
  for (const auto& [key, workers] : {std::pair{"backend.threads", backend.threads}, {"backend.parallel", backend.parallel},
                                     {"backend.fitness_threads", backend.fitness_threads}})
    if (auto m = limits::check(limits::Limit::workers, workers))
      throw CampaignError(source + ": " + key + ": " + *m);
  if (!(backend.max_output_mb > 0) || !(backend.max_output_mb <= 1048576))
    throw CampaignError(source + ": backend.max_output_mb: must be > 0 and <= 1048576 (1 TiB), got " +
                        format_number(backend.max_output_mb, 6));
  if (polish.enabled) {
    try {
      polish.options.Validate();
    } catch (const std::exception& e) {
      throw CampaignError(source + ": polish: " + e.what());
    }
  }
  if (surrogate.enabled || optimiser.algorithm == "bo") {
    try {
      surrogate.options.Validate();
    } catch (const std::exception& e) {
      throw CampaignError(source + ": surrogate: " + e.what());
    }
    if (!surrogate.model_file.empty() && !fs::exists(surrogate.model_file))
      throw CampaignError(source + ": surrogate.model: no such file: " + surrogate.model_file);
    if (surrogate.options.k > optimiser.population)
      throw CampaignError(source + ": surrogate.k = " + std::to_string(surrogate.options.k) +
                          " exceeds the population " + std::to_string(optimiser.population));
  }
  if (!(identifiability_band >= 0) || !std::isfinite(identifiability_band))
    throw CampaignError(source + ": identifiability.relative_band: must be >= 0, got " +
                        std::to_string(identifiability_band));
  if (output.empty()) throw CampaignError(source + ": output: empty output folder");
}

json CampaignConfig::result_defining_json() const {
  json cases_json = json::array();
  for (const auto& c : cases) {
    json scene = scene_to_json_spec(c.scene);
    if (!c.scene.file.empty()) scene["content_hash"] = file_hash(c.scene.file);
    json measured = measured_to_json(c.measured);
    measured["content_hash"] = file_hash(c.measured.file);
    cases_json.push_back({{"name", c.name}, {"scene", scene}, {"measured", measured}, {"weight", c.weight}});
  }
  json objective_json = {{"type", objective}, {"points", objective_options.points},
                         {"weights", objective_options.channel_weights}};
  // absent for the paper's window: older campaigns keep their keys
  if (objective_options.window != smoothing::ObjectiveWindow::common)
    objective_json["window"] = smoothing::to_string(objective_options.window);
  if (objective == 2) objective_json["smoother"] = smoother_to_json(smoother);
  json j = {{"cases", cases_json}, {"parameters", space.to_json()}, {"objective", objective_json},
            {"optimiser", optimiser_to_json(optimiser)}};
  if (backend.type == "command") j["command"] = backend.command;
  if (polish.enabled) j["polish"] = polish_to_json(polish);  // absent otherwise: older keys unchanged
  if (surrogate.enabled || optimiser.algorithm == "bo") j["surrogate"] = surrogate_to_json(surrogate);
  return j;
}

json CampaignConfig::to_json() const {
  json j = result_defining_json();
  j["name"] = name;
  j["backend"] = {{"type", backend.type}, {"threads", backend.threads}, {"command", backend.command},
                  {"timeout_s", backend.timeout_s}, {"parallel", backend.parallel},
                  {"fitness_threads", backend.fitness_threads}, {"max_output_mb", backend.max_output_mb}};
  j["identifiability"] = {{"relative_band", identifiability_band}};
  j["output"] = output;
  j["report"] = report;
  return j;
}

CampaignConfig campaign_from_json(const json& j, const std::string& base_dir, const std::string& source) {
  CampaignConfig c;
  c.source = source;
  reject_unknown_keys(j, {"name", "scene", "measured", "cases", "parameters", "fixed", "tied", "objective",
                          "optimiser", "backend", "output", "archive", "report", "description", "polish",
                          "identifiability", "surrogate"},
                      source);
  read_field(j, "name", c.name, source);
  if (j.contains("cases")) {
    if (j.contains("scene") || j.contains("measured"))
      throw CampaignError(source + ": give either 'cases' or 'scene' + 'measured', not both");
    const json& cases = j.at("cases");
    if (!cases.is_array() || cases.empty()) throw CampaignError(source + ".cases: expected a non-empty array");
    for (size_t i = 0; i < cases.size(); ++i) {
      const std::string where = source + ": cases[" + std::to_string(i) + "]";
      reject_unknown_keys(cases[i], {"name", "scene", "measured", "weight"}, where);
      CaseSpec spec;
      spec.name = "case" + std::to_string(i + 1);
      read_field(cases[i], "name", spec.name, where);
      read_field(cases[i], "weight", spec.weight, where);
      if (cases[i].contains("scene")) spec.scene = parse_scene(cases[i].at("scene"), base_dir, where + ".scene");
      if (cases[i].contains("measured"))
        spec.measured = parse_measured(cases[i].at("measured"), base_dir, where + ".measured");
      c.cases.push_back(spec);
    }
  } else if (j.contains("scene") || j.contains("measured")) {
    CaseSpec spec;
    if (j.contains("scene")) spec.scene = parse_scene(j.at("scene"), base_dir, source + ": scene");
    if (j.contains("measured")) spec.measured = parse_measured(j.at("measured"), base_dir, source + ": measured");
    c.cases.push_back(spec);
  }
  if (j.contains("parameters")) {
    const json& params = j.at("parameters");
    if (!params.is_array()) throw CampaignError(source + ": parameters: expected an array of {name, lower, upper, scale}");
    json space = {{"parameters", json::array()}};
    for (size_t i = 0; i < params.size(); ++i)
      space["parameters"].push_back(normalise_parameter(params[i], source + ": parameters[" + std::to_string(i) + "]"));
    if (j.contains("fixed")) space["fixed"] = j.at("fixed");
    if (j.contains("tied")) space["tied"] = j.at("tied");
    try {
      c.space = optimise::ParameterSpace::from_json(space, source);
    } catch (const std::exception& e) {
      throw CampaignError(e.what());
    }
  }
  if (j.contains("objective")) {
    const json& o = j.at("objective");
    const std::string where = source + ": objective";
    if (o.is_number_integer()) {
      c.objective = o.get<int>();
    } else {
      reject_unknown_keys(o, {"type", "weights", "points", "window", "smoother"}, where);
      read_field(o, "type", c.objective, where);
      read_field(o, "points", c.objective_options.points, where);
      if (o.contains("window")) {
        std::string window;
        read_field(o, "window", window, where);
        try {
          c.objective_options.window = smoothing::parse_objective_window(window);
        } catch (const std::invalid_argument& e) {
          throw CampaignError(where + ".window: " + e.what());
        }
      }
      read_field(o, "weights", c.objective_options.channel_weights, where);
      if (o.contains("smoother")) parse_smoother(o.at("smoother"), c.smoother, where + ".smoother");
    }
  }
  if (j.contains("optimiser")) parse_optimiser(j.at("optimiser"), c.optimiser, source + ": optimiser");
  if (j.contains("backend")) {
    const json& b = j.at("backend");
    const std::string where = source + ": backend";
    if (b.is_string()) {
      c.backend.type = b.get<std::string>();
    } else {
      reject_unknown_keys(b, {"type", "threads", "command", "timeout_s", "parallel", "fitness_threads", "max_output_mb"},
                          where);
      read_field(b, "max_output_mb", c.backend.max_output_mb, where);
      read_field(b, "fitness_threads", c.backend.fitness_threads, where);
      read_field(b, "type", c.backend.type, where);
      read_field(b, "threads", c.backend.threads, where);
      read_field(b, "command", c.backend.command, where);
      read_field(b, "timeout_s", c.backend.timeout_s, where);
      read_field(b, "parallel", c.backend.parallel, where);
    }
  }
  if (j.contains("polish")) parse_polish(j.at("polish"), c.polish, source + ": polish");
  if (j.contains("surrogate")) parse_surrogate(j.at("surrogate"), c.surrogate, source + ": surrogate", base_dir);
  if (j.contains("identifiability")) {
    const std::string where = source + ": identifiability";
    reject_unknown_keys(j.at("identifiability"), {"relative_band"}, where);
    read_field(j.at("identifiability"), "relative_band", c.identifiability_band, where);
  }
  read_field(j, "output", c.output, source);
  read_field(j, "archive", c.archive, source);
  read_field(j, "report", c.report, source);
  c.output = resolve(c.output, base_dir);
  c.archive = resolve(c.archive, base_dir);
  return c;
}

CampaignConfig load_campaign(const std::string& path) {
  if (auto m = limits::check_file_size(path)) throw CampaignError(path + ": " + *m);
  std::ifstream in(path);
  if (!in) throw CampaignError(path + ": cannot open the campaign file");
  json j;
  try {
    j = json::parse(in);
  } catch (const json::parse_error& e) {
    throw CampaignError(path + ": not valid JSON: " + e.what());
  }
  return campaign_from_json(j, fs::path(path).parent_path().string(), path);
}

void add_parameter_flag(optimise::ParameterSpace& space, const std::string& flag) {
  const size_t eq = flag.find('=');
  if (eq == std::string::npos || eq == 0)
    throw CampaignError("--param " + flag + ": expected NAME=LOWER:UPPER[:log], NAME=fixed:VALUE or NAME=tied:SOURCE:RATIO");
  const std::string name = flag.substr(0, eq);
  std::vector<std::string> parts;
  std::stringstream rest(flag.substr(eq + 1));
  for (std::string part; std::getline(rest, part, ':');) parts.push_back(part);
  auto number = [&](const std::string& text) {
    char* end = nullptr;
    const double value = std::strtod(text.c_str(), &end);
    if (text.empty() || *end != '\0' || !std::isfinite(value))
      throw CampaignError("--param " + flag + ": '" + text + "' is not a finite number");
    return value;
  };
  if (!parts.empty() && parts[0] == "fixed" && parts.size() == 2) {
    space.fix(name, number(parts[1]));
  } else if (!parts.empty() && parts[0] == "tied" && parts.size() == 3) {
    space.tie(name, parts[1], number(parts[2]));
  } else if (parts.size() == 2 || parts.size() == 3) {
    auto scale = optimise::ParameterSpec::Scale::linear;
    if (parts.size() == 3) {
      if (parts[2] == "log" || parts[2] == "log10") scale = optimise::ParameterSpec::Scale::log10;
      else if (parts[2] != "linear") throw CampaignError("--param " + flag + ": unknown scale '" + parts[2] + "' (log or linear)");
    }
    space.add(name, number(parts[0]), number(parts[1]), scale);
  } else {
    throw CampaignError("--param " + flag + ": expected NAME=LOWER:UPPER[:log], NAME=fixed:VALUE or NAME=tied:SOURCE:RATIO");
  }
}

ColumnMapping parse_mapping_flag(const std::string& flag) {
  const size_t eq = flag.find('=');
  if (eq == std::string::npos || eq == 0 || eq + 1 == flag.size())
    throw CampaignError("--map " + flag + ": expected TARGET=COLUMN[:UNIT[:SCALE]]");
  ColumnMapping m;
  m.target = flag.substr(0, eq);
  std::vector<std::string> parts;
  std::stringstream rest(flag.substr(eq + 1));
  for (std::string part; std::getline(rest, part, ':');) parts.push_back(part);
  m.column = parts.at(0);
  if (parts.size() > 1) m.unit = parts[1];
  if (parts.size() > 2) {
    char* end = nullptr;
    m.scale = std::strtod(parts[2].c_str(), &end);
    if (*end != '\0' || !std::isfinite(m.scale)) throw CampaignError("--map " + flag + ": bad scale '" + parts[2] + "'");
  }
  if (parts.size() > 3) throw CampaignError("--map " + flag + ": expected TARGET=COLUMN[:UNIT[:SCALE]]");
  unit_factor(m.unit, "--map " + flag);
  return m;
}

smoothing::Curve load_measured(const MeasuredSpec& spec) {
  smoothing::Curve raw;
  try {
    raw = smoothing::read_curve(spec.file);
  } catch (const std::exception& e) {
    throw CampaignError(std::string("measured curve: ") + e.what());
  }
  std::vector<ColumnMapping> mapping = spec.columns;
  if (mapping.empty())
    for (const auto& column : raw.columns) mapping.push_back({column.name, column.name, "", 1});
  smoothing::Curve out;
  out.source = spec.file;
  out.preamble = raw.preamble;
  bool has_force = false;
  for (const auto& m : mapping) {
    if (!raw.has_column(m.column)) {
      std::string names;
      for (const auto& n : raw.column_names()) names += (names.empty() ? "" : ", ") + n;
      throw CampaignError(spec.file + ": no column '" + m.column + "' for '" + m.target + "' (columns: " + names + ")");
    }
    const auto& source = raw.column(m.column);
    const std::string unit = m.unit.empty() ? source.unit : m.unit;
    const double factor = unit_factor(unit, spec.file + ": column '" + m.column + "'") * m.scale;
    smoothing::Column column;
    column.name = m.target;
    column.unit = m.target == "force" ? "N" : (m.target == "time" ? "s" : "m");
    column.values.reserve(source.values.size());
    for (double v : source.values) column.values.push_back(v * factor);
    has_force = has_force || m.target == "force";
    out.columns.push_back(std::move(column));
  }
  if (!has_force)
    throw CampaignError(spec.file + ": no 'force' column after mapping (map one with columns.force or --map force=COLUMN:UNIT)");
  if (out.columns.size() < 2)
    throw CampaignError(spec.file + ": no displacement column after mapping (map a gauge name to a column)");
  return out;
}

namespace {
template <class T>
void option(const json& j, const char* key, T& out, const std::string& where) {
  read_field(j, key, out, where);
}

// The scene of a file or a generator, as it comes.
dem::Scene generate_scene(const SceneSpec& spec, const std::string& where) {
  if (!spec.file.empty()) return dem::load_scene(spec.file);
  const json& o = spec.options;
  const std::string at = where + ".options";
  if (spec.generator == "arch") {
    reject_unknown_keys(o, {"span", "rise", "thickness", "width", "voussoirs", "density", "kn", "ks", "friction_deg",
                            "contacts_per_joint", "load_voussoir", "interface_height", "interface_length",
                            "velocity", "max_displacement", "record_interval", "load", "max_time", "abutment_depth"},
                        at);
    dem::ArchOptions a;
    option(o, "span", a.span, at);
    option(o, "rise", a.rise, at);
    option(o, "thickness", a.thickness, at);
    option(o, "width", a.width, at);
    option(o, "voussoirs", a.voussoirs, at);
    option(o, "density", a.density, at);
    option(o, "kn", a.kn, at);
    option(o, "ks", a.ks, at);
    option(o, "friction_deg", a.friction_deg, at);
    option(o, "contacts_per_joint", a.contacts_per_joint, at);
    option(o, "load_voussoir", a.load_voussoir, at);
    option(o, "interface_height", a.interface_height, at);
    option(o, "interface_length", a.interface_length, at);
    option(o, "velocity", a.velocity, at);
    option(o, "max_displacement", a.max_displacement, at);
    option(o, "record_interval", a.record_interval, at);
    option(o, "load", a.load, at);
    option(o, "max_time", a.max_time, at);
    option(o, "abutment_depth", a.abutment_depth, at);
    a.Validate();
    return dem::make_arch(a);
  }
  if (spec.generator == "wall") {
    reject_unknown_keys(o, {"height", "length", "thickness", "unit_height", "unit_length", "density",
                            "precompression_mpa", "kn", "ks", "friction_deg", "contacts_per_joint", "velocity",
                            "max_displacement", "record_interval", "beam_rotation", "beam_height", "load_height", "max_time"},
                        at);
    dem::WallOptions w;
    option(o, "height", w.height, at);
    option(o, "length", w.length, at);
    option(o, "thickness", w.thickness, at);
    option(o, "unit_height", w.unit_height, at);
    option(o, "unit_length", w.unit_length, at);
    option(o, "density", w.density, at);
    option(o, "precompression_mpa", w.precompression_mpa, at);
    option(o, "kn", w.kn, at);
    option(o, "ks", w.ks, at);
    option(o, "friction_deg", w.friction_deg, at);
    option(o, "contacts_per_joint", w.contacts_per_joint, at);
    option(o, "velocity", w.velocity, at);
    option(o, "max_displacement", w.max_displacement, at);
    option(o, "record_interval", w.record_interval, at);
    option(o, "beam_rotation", w.beam_rotation, at);
    option(o, "beam_height", w.beam_height, at);
    option(o, "load_height", w.load_height, at);
    option(o, "max_time", w.max_time, at);
    w.Validate();
    return dem::make_wall(w);
  }
  throw CampaignError(where + ": no scene file or generator");
}

// The spec's solver settings laid over the scene's, validated as a scene file's would be.
dem::Scene with_solver_settings(dem::Scene scene, const SceneSpec& spec, const std::string& where) {
  if (spec.solver.empty()) return scene;
  json j = dem::scene_to_json(scene);
  j["solver"].update(spec.solver);
  scene.solver = dem::scene_from_json(j, where).solver;  // the rest kept as built, bit for bit
  return scene;
}

}  // namespace

dem::Scene build_scene(const SceneSpec& spec, const std::string& where) {
  return with_solver_settings(generate_scene(spec, where), spec, where);
}

}  // namespace demcal::pipelines
