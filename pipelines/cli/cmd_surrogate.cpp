// `demcal surrogate train|check`: a surrogate model of the fitness trained from an archive's runs
// (surrogate.hpp, surrogate_data.hpp; docs/surrogate.md).
#include "command_registry.hpp"

#include "demcal/pipelines/archive.hpp"
#include "demcal/pipelines/campaign.hpp"
#include "demcal/pipelines/surrogate_data.hpp"

#include <filesystem>
#include <fstream>
#include <iostream>
#include <memory>

namespace demcal::cli::surrogate_command {

using nlohmann::json;

struct Flags {
  std::string archive, scene_hash, objective_key, out, kind, campaign;
  int folds = 5;
};

json problem_json(const demcal::pipelines::ArchivedProblem& p) {
  long failed = 0;
  for (const auto& r : p.rows) failed += std::isfinite(r.fitness) ? 0 : 1;
  return {{"scene_hash", p.model_hash}, {"objective_key", p.objective_key}, {"campaign", p.campaign_name},
          {"parameters", p.space.free_names()}, {"rows", p.rows.size()}, {"failed_rows", failed}};
}

// The problem and, for the "mlp" kind, its rows' curves and the fitness of predicted ones: the
// measurement is that of the campaign file's case whose objective key is the problem's.
struct LoadedProblem {
  demcal::pipelines::ArchivedProblem problem;
  demcal::surrogate::CurveHooks hooks;
};

LoadedProblem load(const Flags& f) {
  using namespace demcal::pipelines;
  if (!std::filesystem::exists(f.archive)) throw std::runtime_error(f.archive + ": no such archive");
  RunArchive archive(f.archive);
  LoadedProblem loaded{find_archived_problem(archive, f.scene_hash, f.objective_key), {}};
  auto& p = loaded.problem;
  if (!f.kind.empty()) p.options.kind = f.kind;
  p.options.Validate();
  if (p.options.kind != "mlp") return loaded;
  if (f.campaign.empty())
    throw std::runtime_error("the mlp kind predicts curves and needs the measurement they are scored against: "
                             "name the campaign file with --campaign");
  std::shared_ptr<CurveGrid> grid;
  for (const auto& g : campaign_curve_grids(load_campaign(f.campaign)))
    if (g.objective_key == p.objective_key) grid = std::make_shared<CurveGrid>(*g.grid);
  if (!grid)
    throw std::runtime_error(f.campaign + ": no case of this campaign has objective key " + p.objective_key +
                             " (the archive's runs were scored against another measurement, objective or smoother)");
  grid->case_weight = 1.0;  // the rows are one scene's fitness, unweighted
  std::vector<ArchivedCase> cases = {{p.model_hash, p.objective_key, 1.0, grid}};
  p.rows = archive_training_rows(archive, p.space, cases);
  loaded.hooks.fitness = [grid = std::shared_ptr<const CurveGrid>(grid)](const Eigen::VectorXd& outputs) {
    return curve_fitness(outputs, {grid});
  };
  return loaded;
}

void train(const Flags& f) {
  const auto loaded = load(f);
  const auto& problem = loaded.problem;
  demcal::surrogate::SurrogateModel model(problem.options, loaded.hooks);
  if (!model.fit(problem.rows))
    throw std::runtime_error(f.archive + ": fewer than 3 runs with a finite fitness for scene hash " + problem.model_hash);
  {
    std::ofstream out(f.out);
    json file = model.to_json();
    file["trained_on"] = problem_json(problem);
    file["trained_on"]["archive"] = f.archive;
    out << file.dump(1) << "\n";
    if (!out) throw std::runtime_error(f.out + ": cannot write the model");
  }
  json summary = problem_json(problem);
  summary["model"] = f.out;
  summary["kind"] = model.options().kind;
  summary["log_transform"] = model.log_transformed();
  if (model.options().kind == "gp") {
    const auto loo = model.gp().leave_one_out();
    json lengths = json::array();
    for (Eigen::Index k = 0; k < model.gp().length_scales().size(); ++k) lengths.push_back(model.gp().length_scales()[k]);
    summary["length_scales"] = lengths;
    summary["noise_sd"] = model.gp().noise_sd();
    summary["loo"] = {{"mean_absolute_error", loo.mean_absolute_error}, {"relative_error", loo.relative_error},
                      {"coverage90", loo.coverage90}};
  } else {
    summary["members"] = model.ensemble().members();
    summary["outputs"] = model.ensemble().outputs();
  }
  std::cout << summary.dump(2) << "\n";
}

void check(const Flags& f) {
  const auto loaded = load(f);
  const auto& problem = loaded.problem;
  const auto cv = demcal::surrogate::cross_validate(problem.rows, problem.options, f.folds, loaded.hooks);
  json summary = problem_json(problem);
  summary["kind"] = problem.options.kind;
  summary["cross_validation"] = cv.to_json();
  std::cout << summary.dump(2) << "\n";
  if (cv.finite_rows == 0) {
    std::cerr << "demcal: " << f.archive << ": too few runs to cross-validate\n";
    demcal::cli::exit_code() = 2;
  }
}

void setup(CLI::App& app) {
  auto* sub = app.add_subcommand("surrogate", "Surrogate models of the fitness trained from an archive's runs");
  sub->require_subcommand(1);
  auto add_common = [](CLI::App* cmd, Flags& flags) {
    cmd->add_option("--archive", flags.archive, "Run archive (archive.sqlite of a campaign)")->required();
    cmd->add_option("--scene-hash", flags.scene_hash, "Scene (model) hash; default: the one with most scored runs");
    cmd->add_option("--objective-key", flags.objective_key, "Objective key; default: the scene's most used one");
    cmd->add_option("--kind", flags.kind, "Model kind: gp | mlp; default: that of the newest campaign that ran the scene")
        ->check(CLI::IsMember({"gp", "mlp"}));
    cmd->add_option("--campaign", flags.campaign,
                    "Campaign file whose measurement scores the predicted curves (needed by the mlp kind)");
  };
  auto train_flags = std::make_shared<Flags>();
  auto* t = sub->add_subcommand("train", "Fit the model on every finished run of one scene; write it as JSON");
  add_common(t, *train_flags);
  t->add_option("--out", train_flags->out, "Model file to write (JSON)")->required();
  t->callback([train_flags] { train(*train_flags); });
  auto check_flags = std::make_shared<Flags>();
  auto* c = sub->add_subcommand("check", "Cross-validated error and coverage of the 90 % intervals (JSON)");
  add_common(c, *check_flags);
  c->add_option("--folds", check_flags->folds, "Cross-validation folds (>= 2)")->check(CLI::Range(2, 1000));
  c->callback([check_flags] { check(*check_flags); });
}

}  // namespace demcal::cli::surrogate_command

DEMCAL_REGISTER_COMMAND("surrogate", demcal::cli::surrogate_command::setup);
