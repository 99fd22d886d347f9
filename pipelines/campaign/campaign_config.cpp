#include "demcal/pipelines/archive.hpp"
#include "demcal/pipelines/campaign.hpp"

#include "demcal/common/field_table.hpp"
#include "demcal/common/format.hpp"
#include "demcal/dem/generators.hpp"
#include "demcal/limits/limits.hpp"

#include <cmath>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>

namespace demcal::pipelines {

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

// Reads `j` into `options` by `fields`. An error a field words itself (a named value's unknown
// name; for an unchecked field, JSON that is no string) is reported as "<where>: <what>".
template <class Options>
void read_fields(const FieldTable<Options>& fields, const json& j, Options& options, const std::string& where) {
  try {
    fields.template read<CampaignError>(j, options, where);
  } catch (const CampaignError&) {
    throw;
  } catch (const std::exception& e) {
    throw CampaignError(where + ": " + e.what());
  }
}

// An enum value's name, by its module's to_string.
const auto name_of = [](auto value) { return to_string(value); };

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

// The scene file's solver keys (dem::scene_from_json reads them when the scene is built).
const std::set<std::string> kSolverKeys{"local_damping",         "time_step_safety",     "time_step",
                                        "time_step_faces",       "time_step_stiffening", "density_scaling",
                                        "equilibrium_ratio",     "max_equilibrium_time", "max_time",
                                        "collapse_displacement", "max_velocity"};

// `value`'s JSON, or nullopt (left out) when it is empty.
template <class T>
std::optional<json> unless_empty(const T& value) {
  if (value.empty()) return std::nullopt;
  return json(value);
}

// Written with what is set: "options" only with a generator.
const FieldTable<SceneSpec>& scene_fields() {
  static const FieldTable<SceneSpec> table{
      field("file", &SceneSpec::file).writes([](const SceneSpec& s) { return unless_empty(s.file); }),
      field("generator", &SceneSpec::generator).writes([](const SceneSpec& s) { return unless_empty(s.generator); }),
      field("options", &SceneSpec::options).writes([](const SceneSpec& s) {
        return s.generator.empty() ? std::nullopt : std::optional<json>(s.options);
      }),
      custom_field<SceneSpec>(
          "solver",
          [](SceneSpec& s, const json& value, const std::string& where) {
            s.solver = value;
            reject_unknown_keys<CampaignError>(s.solver, kSolverKeys, where + ".solver");
          },
          [](const SceneSpec& s) { return unless_empty(s.solver); }),
  };
  return table;
}

// A scene file name or an object; relative file names are resolved by campaign_from_json.
SceneSpec parse_scene(const json& j, const std::string& where) {
  SceneSpec spec;
  if (j.is_string()) {
    spec.file = j.get<std::string>();
    return spec;
  }
  read_fields(scene_fields(), j, spec, where);
  if (!spec.file.empty() && !spec.generator.empty())
    throw CampaignError(where + ": give either 'file' or 'generator', not both");
  if (!spec.generator.empty() && spec.generator != "arch" && spec.generator != "wall")
    throw CampaignError(where + ".generator: unknown generator '" + spec.generator + "' (known: arch, wall)");
  return spec;
}

const FieldTable<ColumnMapping>& column_fields() {
  static const FieldTable<ColumnMapping> table{
      field("column", &ColumnMapping::column),
      field("unit", &ColumnMapping::unit),
      field("scale", &ColumnMapping::scale),
  };
  return table;
}

void read_columns(MeasuredSpec& spec, const json& columns, const std::string& where) {
  if (!columns.is_object()) throw CampaignError(where + ".columns: expected an object target -> {column, unit}");
  for (const auto& [target, value] : columns.items()) {
    ColumnMapping m;
    m.target = target;
    const std::string at = where + ".columns." + target;
    if (value.is_string()) m.column = value.get<std::string>();
    else read_fields(column_fields(), value, m, at);
    if (m.column.empty()) throw CampaignError(at + ": missing 'column' (the file's column name)");
    unit_factor(m.unit, at + ".unit");
    spec.columns.push_back(m);
  }
}

const FieldTable<MeasuredSpec>& measured_fields() {
  static const FieldTable<MeasuredSpec> table{
      field("file", &MeasuredSpec::file),
      custom_field<MeasuredSpec>("columns", read_columns, [](const MeasuredSpec& m) -> std::optional<json> {
        json columns = json::object();
        for (const auto& c : m.columns) columns[c.target] = column_fields().to_json(c);
        return columns;
      }),
  };
  return table;
}

// A file name or an object; relative file names are resolved by campaign_from_json.
MeasuredSpec parse_measured(const json& j, const std::string& where) {
  MeasuredSpec spec;
  if (j.is_string()) spec.file = j.get<std::string>();
  else read_fields(measured_fields(), j, spec, where);
  return spec;
}

// Written with the content hash of each file, part of the campaign's key.
const FieldTable<CaseSpec>& case_fields() {
  static const FieldTable<CaseSpec> table{
      field("name", &CaseSpec::name),
      field("weight", &CaseSpec::weight),
      custom_field<CaseSpec>(
          "scene",
          [](CaseSpec& c, const json& value, const std::string& where) {
            c.scene = parse_scene(value, where + ".scene");
          },
          [](const CaseSpec& c) -> std::optional<json> {
            json scene = scene_fields().to_json(c.scene);
            if (!c.scene.file.empty()) scene["content_hash"] = file_hash(c.scene.file);
            return scene;
          }),
      custom_field<CaseSpec>(
          "measured",
          [](CaseSpec& c, const json& value, const std::string& where) {
            c.measured = parse_measured(value, where + ".measured");
          },
          [](const CaseSpec& c) -> std::optional<json> {
            json measured = measured_fields().to_json(c.measured);
            measured["content_hash"] = file_hash(c.measured.file);
            return measured;
          }),
  };
  return table;
}

const FieldTable<optimise::PolishOptions>& polish_fields() {
  using optimise::PolishOptions;
  static const FieldTable<PolishOptions> table{
      field("algorithm", &PolishOptions::algorithm),
      field("max_evaluations", &PolishOptions::max_evaluations),
      field("initial_step", &PolishOptions::initial_step),
      field("xtol_rel", &PolishOptions::xtol_rel),
  };
  return table;
}

// Every option that changes a smoothed curve is here: it is part of the objective key under which
// the archive keeps fitness values, so values of another smoother are never read back.
const FieldTable<smoothing::SmootherOptions>& smoother_fields() {
  using smoothing::SmootherOptions;
  static const FieldTable<SmootherOptions> table{
      field("points", &SmootherOptions::points),
      field("hidden_layers", &SmootherOptions::hidden_layers),
      field("hidden_width", &SmootherOptions::hidden_width),
      field("epochs", &SmootherOptions::epochs),
      field("learning_rate", &SmootherOptions::learning_rate),
      field("final_learning_rate", &SmootherOptions::final_learning_rate),
      field("first_layer_gain", &SmootherOptions::first_layer_gain),
      field("check_interval", &SmootherOptions::check_interval),
      field("trend_cutoff", &SmootherOptions::trend_cutoff),
      field("seed", &SmootherOptions::seed),
      field("threads", &SmootherOptions::threads),
      named_field("stopping", &SmootherOptions::stopping, smoothing::parse_stopping_rule, name_of),
      named_field("backend", &SmootherOptions::backend, smoothing::parse_smoother_backend, name_of),
  };
  return table;
}

// The objective's window: read as a named value, its parse message prefixed with the key (it does
// not name it); absent for the paper's window, so older campaigns keep their keys.
Field<CampaignConfig> objective_window_field() {
  auto window = named_field<CampaignConfig>("window", [](auto& c) -> auto& { return c.objective_options.window; },
                                            smoothing::parse_objective_window, name_of);
  window.read = [parse = window.read](CampaignConfig& c, const json& value, const std::string& where) {
    try {
      parse(c, value, where);
    } catch (const std::invalid_argument& e) {
      throw CampaignError(where + ".window: " + e.what());
    }
  };
  return std::move(window).writes([](const CampaignConfig& c) -> std::optional<json> {
    if (c.objective_options.window == smoothing::ObjectiveWindow::common) return std::nullopt;
    return smoothing::to_string(c.objective_options.window);
  });
}

// The "objective" object: CampaignConfig's objective type and options, and the smoother of
// objective 2 (written only for objective 2).
const FieldTable<CampaignConfig>& objective_fields() {
  static const FieldTable<CampaignConfig> table{
      field("type", &CampaignConfig::objective),
      field<CampaignConfig>("points", [](auto& c) -> auto& { return c.objective_options.points; }),
      objective_window_field(),
      field<CampaignConfig>("weights", [](auto& c) -> auto& { return c.objective_options.channel_weights; }),
      custom_field<CampaignConfig>(
          "smoother",
          [](CampaignConfig& c, const json& value, const std::string& where) {
            read_fields(smoother_fields(), value, c.smoother, where + ".smoother");
          },
          [](const CampaignConfig& c) -> std::optional<json> {
            if (c.objective != 2) return std::nullopt;
            return smoother_fields().to_json(c.smoother);
          }),
  };
  return table;
}

const FieldTable<BackendSpec>& backend_fields() {
  static const FieldTable<BackendSpec> table{
      field("max_output_mb", &BackendSpec::max_output_mb),
      field("fitness_threads", &BackendSpec::fitness_threads),
      field("type", &BackendSpec::type),
      field("threads", &BackendSpec::threads),
      field("command", &BackendSpec::command),
      field("timeout_s", &BackendSpec::timeout_s),
      field("parallel", &BackendSpec::parallel),
  };
  return table;
}

const FieldTable<CampaignConfig>& identifiability_fields() {
  static const FieldTable<CampaignConfig> table{
      field("relative_band", &CampaignConfig::identifiability_band),
      custom_field<CampaignConfig>(
          "profile",
          [](CampaignConfig& c, const json& value, const std::string& where) {
            try {
              c.identifiability_profile = surrogate::ProfileOptions::from_json(value, where + ".profile");
            } catch (const std::invalid_argument& e) {
              throw CampaignError(e.what());
            }
          },
          [](const CampaignConfig& c) -> std::optional<json> { return c.identifiability_profile.to_json(); }),
  };
  return table;
}

// A parameter entry with "log"/"log10"/"linear" scale and lower/upper (min/max accepted).
json normalise_parameter(json p, const std::string& where) {
  if (!p.is_object()) throw CampaignError(where + ": expected {name, lower, upper, scale}, got " + describe_json(p));
  reject_unknown_keys<CampaignError>(p, {"name", "lower", "upper", "min", "max", "scale"}, where);
  if (p.contains("min")) p["lower"] = p["min"], p.erase("min");
  if (p.contains("max")) p["upper"] = p["max"], p.erase("max");
  if (p.contains("scale") && p["scale"].is_string() && p["scale"] == "log") p["scale"] = "log10";
  for (const char* key : {"lower", "upper"}) {
    if (!p.contains(key)) throw CampaignError(where + ": missing '" + key + "'");
    if (!p[key].is_number()) throw CampaignError(where + "." + key + ": not a number: " + describe_json(p[key]));
  }
  return p;
}

}  // namespace

// Read in this order (the first bad value is reported), the enums last; these are unchecked: JSON
// that is no string is reported as "<where>: <nlohmann's message>", as campaigns always were.
const FieldTable<optimise::OptimiserOptions>& optimiser_fields() {
  using optimise::OptimiserOptions;
  static const FieldTable<OptimiserOptions> table{
      field("algorithm", &OptimiserOptions::algorithm).flag("pso | tbpso | ga | nlopt:<NAME> (e.g. nlopt:LN_BOBYQA)"),
      field("population", &OptimiserOptions::population),
      field("iterations", &OptimiserOptions::iterations),
      field("max_evaluations", &OptimiserOptions::max_evaluations),
      field("seed", &OptimiserOptions::seed).flag("Random seed"),
      field("target_value", &OptimiserOptions::target_value).writes([](const OptimiserOptions& o) {
        return std::optional<json>(finite_or_null(o.target_value));  // the default -infinity: null
      }),
      field("inertia_start", &OptimiserOptions::inertia_start),
      field("inertia_end", &OptimiserOptions::inertia_end),
      field("pso_cognitive", &OptimiserOptions::pso_cognitive),
      field("pso_social", &OptimiserOptions::pso_social),
      field("tbpso_cognitive", &OptimiserOptions::tbpso_cognitive),
      field("tbpso_social", &OptimiserOptions::tbpso_social),
      field("tbpso_trust", &OptimiserOptions::tbpso_trust),
      field("constriction", &OptimiserOptions::constriction)
          .flag("PSO/TBPSO: multiply by the constriction factor K (eq. 8)"),
      field("max_velocity", &OptimiserOptions::max_velocity),
      field("initial_velocity", &OptimiserOptions::initial_velocity),
      field("trust_direction", &OptimiserOptions::trust_direction)
          .flag("TBPSO reading of dx: toward (x_j - x_i) | paper (x_i - x_j)"),
      field("crossover_probability", &OptimiserOptions::crossover_probability),
      field("mutation_probability", &OptimiserOptions::mutation_probability),
      field("ga_sigma_start", &OptimiserOptions::ga_sigma_start),
      field("ga_sigma_end", &OptimiserOptions::ga_sigma_end),
      field("elitism", &OptimiserOptions::elitism).flag("GA: individuals kept unchanged per generation"),
      field("initial_step", &OptimiserOptions::initial_step),
      field("nlopt_population", &OptimiserOptions::nlopt_population),
      field("xtol_rel", &OptimiserOptions::xtol_rel),
      field("ftol_abs", &OptimiserOptions::ftol_abs),
      named_field("bounds", &OptimiserOptions::bounds, optimise::parse_bound_handling, name_of)
          .unchecked()
          .flag("PSO/TBPSO bound handling: clamp | reflect"),
      named_field("ga_mutation", &OptimiserOptions::ga_mutation, optimise::parse_ga_mutation, name_of)
          .unchecked()
          .flag("GA mutation: reset (paper) | gaussian"),
  };
  return table;
}

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
  for (const auto& c : cases) cases_json.push_back(case_fields().to_json(c));
  json j = {{"cases", cases_json}, {"parameters", space.to_json()}, {"objective", objective_fields().to_json(*this)},
            {"optimiser", optimiser_fields().to_json(optimiser)}};
  if (backend.type == "command") j["command"] = backend.command;
  if (polish.enabled) j["polish"] = polish_fields().to_json(polish.options);  // absent otherwise: older keys unchanged
  if (surrogate.enabled || optimiser.algorithm == "bo") j["surrogate"] = surrogate_to_json(surrogate);
  return j;
}

json CampaignConfig::to_json() const {
  json j = result_defining_json();
  j["name"] = name;
  j["backend"] = backend_fields().to_json(backend);
  j["identifiability"] = identifiability_fields().to_json(*this);
  j["output"] = output;
  j["report"] = report;
  return j;
}

CampaignConfig campaign_from_json(const json& j, const std::string& base_dir, const std::string& source) {
  CampaignConfig c;
  c.source = source;
  reject_unknown_keys<CampaignError>(j, {"name", "scene", "measured", "cases", "parameters", "fixed", "tied", "objective",
                          "optimiser", "backend", "output", "archive", "report", "description", "polish",
                          "identifiability", "surrogate"},
                      source);
  read_field<CampaignError>(j, "name", c.name, source);
  if (j.contains("cases")) {
    if (j.contains("scene") || j.contains("measured"))
      throw CampaignError(source + ": give either 'cases' or 'scene' + 'measured', not both");
    const json& cases = j.at("cases");
    if (!cases.is_array() || cases.empty()) throw CampaignError(source + ".cases: expected a non-empty array");
    for (size_t i = 0; i < cases.size(); ++i) {
      const std::string where = source + ": cases[" + std::to_string(i) + "]";
      CaseSpec spec;
      spec.name = "case" + std::to_string(i + 1);
      read_fields(case_fields(), cases[i], spec, where);
      c.cases.push_back(spec);
    }
  } else if (j.contains("scene") || j.contains("measured")) {
    CaseSpec spec;
    if (j.contains("scene")) spec.scene = parse_scene(j.at("scene"), source + ": scene");
    if (j.contains("measured")) spec.measured = parse_measured(j.at("measured"), source + ": measured");
    c.cases.push_back(spec);
  }
  for (auto& spec : c.cases) {
    spec.scene.file = resolve(spec.scene.file, base_dir);
    spec.measured.file = resolve(spec.measured.file, base_dir);
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
      read_fields(objective_fields(), o, c, where);
    }
  }
  if (j.contains("optimiser")) read_fields(optimiser_fields(), j.at("optimiser"), c.optimiser, source + ": optimiser");
  if (j.contains("backend")) {
    const json& b = j.at("backend");
    const std::string where = source + ": backend";
    if (b.is_string()) {
      c.backend.type = b.get<std::string>();
    } else {
      read_fields(backend_fields(), b, c.backend, where);
    }
  }
  if (j.contains("polish")) {
    read_fields(polish_fields(), j.at("polish"), c.polish.options, source + ": polish");
    c.polish.enabled = true;
  }
  if (j.contains("surrogate")) parse_surrogate(j.at("surrogate"), c.surrogate, source + ": surrogate", base_dir);
  if (j.contains("identifiability"))
    read_fields(identifiability_fields(), j.at("identifiability"), c, source + ": identifiability");
  read_field<CampaignError>(j, "output", c.output, source);
  read_field<CampaignError>(j, "archive", c.archive, source);
  read_field<CampaignError>(j, "report", c.report, source);
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

// The generators' options (scene.options): ArchOptions and WallOptions fields by name.
const FieldTable<dem::ArchOptions>& arch_fields() {
  using dem::ArchOptions;
  static const FieldTable<ArchOptions> table{
      field("span", &ArchOptions::span),
      field("rise", &ArchOptions::rise),
      field("thickness", &ArchOptions::thickness),
      field("width", &ArchOptions::width),
      field("voussoirs", &ArchOptions::voussoirs),
      field("density", &ArchOptions::density),
      field("kn", &ArchOptions::kn),
      field("ks", &ArchOptions::ks),
      field("friction_deg", &ArchOptions::friction_deg),
      field("contacts_per_joint", &ArchOptions::contacts_per_joint),
      field("load_voussoir", &ArchOptions::load_voussoir),
      field("interface_height", &ArchOptions::interface_height),
      field("interface_length", &ArchOptions::interface_length),
      field("velocity", &ArchOptions::velocity),
      field("max_displacement", &ArchOptions::max_displacement),
      field("record_interval", &ArchOptions::record_interval),
      field("load", &ArchOptions::load),
      field("max_time", &ArchOptions::max_time),
      field("abutment_depth", &ArchOptions::abutment_depth),
  };
  return table;
}

const FieldTable<dem::WallOptions>& wall_fields() {
  using dem::WallOptions;
  static const FieldTable<WallOptions> table{
      field("height", &WallOptions::height),
      field("length", &WallOptions::length),
      field("thickness", &WallOptions::thickness),
      field("unit_height", &WallOptions::unit_height),
      field("unit_length", &WallOptions::unit_length),
      field("density", &WallOptions::density),
      field("precompression_mpa", &WallOptions::precompression_mpa),
      field("kn", &WallOptions::kn),
      field("ks", &WallOptions::ks),
      field("friction_deg", &WallOptions::friction_deg),
      field("contacts_per_joint", &WallOptions::contacts_per_joint),
      field("velocity", &WallOptions::velocity),
      field("max_displacement", &WallOptions::max_displacement),
      field("record_interval", &WallOptions::record_interval),
      field("beam_rotation", &WallOptions::beam_rotation),
      field("beam_height", &WallOptions::beam_height),
      field("load_height", &WallOptions::load_height),
      field("max_time", &WallOptions::max_time),
  };
  return table;
}

// The scene of a file or a generator, as it comes.
dem::Scene generate_scene(const SceneSpec& spec, const std::string& where) {
  if (!spec.file.empty()) return dem::load_scene(spec.file);
  const std::string at = where + ".options";
  if (spec.generator == "arch") {
    dem::ArchOptions a;
    read_fields(arch_fields(), spec.options, a, at);
    a.Validate();
    return dem::make_arch(a);
  }
  if (spec.generator == "wall") {
    dem::WallOptions w;
    read_fields(wall_fields(), spec.options, w, at);
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
