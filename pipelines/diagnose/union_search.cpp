// Stage 4b of the diagnosis, the union search (DiagnoseOptions::union_rounds): one emulator of the
// curves over the base parameters and every calibrated candidate's (UnionLayout), trained on every
// archived run of those models, searched for each candidate from many starts; the best points of
// each simulated per round (one per candidate, more where the workers outnumber the candidates),
// and the best of a candidate's proposals kept where it fits better than its calibration did.
#include "diagnose_internal.hpp"

#include "demcal/pipelines/backend.hpp"
#include "demcal/pipelines/surrogate_data.hpp"
#include "demcal/surrogate/curve_ensemble.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <random>
#include <set>

namespace demcal::pipelines {

namespace fs = std::filesystem;
using namespace detail;

UnionLayout::UnionLayout(optimise::ParameterSpace base) : base_(std::move(base)), dimension_(base_.dimension()) {}

int UnionLayout::add_model(const optimise::ParameterSpace& space) {
  Block b;
  b.space = space;
  const auto base_names = base_.free_names();
  for (const auto& name : space.free_names()) {
    if (std::find(base_names.begin(), base_names.end(), name) != base_names.end()) continue;
    b.own.push_back(name);
  }
  b.offset = dimension_;
  dimension_ += 1 + static_cast<Eigen::Index>(b.own.size());
  blocks_.push_back(std::move(b));
  return models() - 1;
}

namespace {

// The unit value of `value` for `spec`, clipped to [0, 1]; NaN when it is not finite.
double unit_of(const optimise::ParameterSpec& spec, double value) {
  if (!std::isfinite(value)) return std::numeric_limits<double>::quiet_NaN();
  optimise::ParameterSpace one;
  one.add(spec);
  return std::clamp(one.to_unit(Eigen::VectorXd::Constant(1, value))(0), 0.0, 1.0);
}

double physical_of(const optimise::ParameterSpec& spec, double unit) {
  optimise::ParameterSpace one;
  one.add(spec);
  return one.to_physical(Eigen::VectorXd::Constant(1, std::clamp(unit, 0.0, 1.0)))(0);
}

const optimise::ParameterSpec& spec_of(const optimise::ParameterSpace& space, const std::string& name) {
  for (const auto& p : space.free_parameters())
    if (p.name == name) return p;
  throw std::invalid_argument("union search: " + name + " is not a free parameter of the model");
}

// The models switched on for model `model` (-1: the base, none).
std::vector<int> models_on(int model) { return model < 0 ? std::vector<int>{} : std::vector<int>{model}; }

}  // namespace

Eigen::VectorXd UnionLayout::point(int model, const std::map<std::string, double>& params) const {
  return point(models_on(model), params);
}
Eigen::VectorXd UnionLayout::switched(int model, Eigen::VectorXd x) const { return switched(models_on(model), std::move(x)); }
std::vector<Eigen::Index> UnionLayout::coordinates(int model) const { return coordinates(models_on(model)); }
std::map<std::string, double> UnionLayout::parameters(int model, const Eigen::VectorXd& x) const {
  return parameters(models_on(model), x);
}

Eigen::VectorXd UnionLayout::point(const std::vector<int>& on, const std::map<std::string, double>& params) const {
  Eigen::VectorXd x = switched(on, Eigen::VectorXd::Constant(dimension_, 0.5));
  const auto value = [&](const std::string& name) {
    const auto it = params.find(name);
    return it == params.end() ? std::numeric_limits<double>::quiet_NaN() : it->second;
  };
  const auto& base = base_.free_parameters();
  for (std::size_t k = 0; k < base.size(); ++k) {
    x(static_cast<Eigen::Index>(k)) = unit_of(base[k], value(base[k].name));
    if (std::isnan(x(static_cast<Eigen::Index>(k)))) return {};
  }
  for (const int model : on) {
    const Block& b = blocks_.at(static_cast<std::size_t>(model));
    for (std::size_t k = 0; k < b.own.size(); ++k) {
      const Eigen::Index at = b.offset + 1 + static_cast<Eigen::Index>(k);
      x(at) = unit_of(spec_of(b.space, b.own[k]), value(b.own[k]));
      if (std::isnan(x(at))) return {};
    }
  }
  return x;
}

Eigen::VectorXd UnionLayout::switched(const std::vector<int>& on, Eigen::VectorXd x) const {
  for (int m = 0; m < models(); ++m) {
    const Block& b = blocks_[static_cast<std::size_t>(m)];
    const bool is_on = std::find(on.begin(), on.end(), m) != on.end();
    x(b.offset) = is_on ? 1.0 : 0.0;
    if (!is_on) x.segment(b.offset + 1, static_cast<Eigen::Index>(b.own.size())).setConstant(0.5);
  }
  return x;
}

std::vector<Eigen::Index> UnionLayout::coordinates(const std::vector<int>& on) const {
  std::vector<Eigen::Index> c;
  for (Eigen::Index k = 0; k < base_.dimension(); ++k) c.push_back(k);
  for (const int model : on) {
    const Block& b = blocks_.at(static_cast<std::size_t>(model));
    for (std::size_t k = 0; k < b.own.size(); ++k) c.push_back(b.offset + 1 + static_cast<Eigen::Index>(k));
  }
  return c;
}

std::map<std::string, double> UnionLayout::parameters(const std::vector<int>& on, const Eigen::VectorXd& x) const {
  std::map<std::string, double> params;
  const auto& base = base_.free_parameters();
  for (std::size_t k = 0; k < base.size(); ++k) {
    double v = physical_of(base[k], x(static_cast<Eigen::Index>(k)));
    for (const int model : on) {  // a model's box may be narrower
      const optimise::ParameterSpec& box = spec_of(blocks_.at(static_cast<std::size_t>(model)).space, base[k].name);
      v = std::clamp(v, box.lower, box.upper);
    }
    params[base[k].name] = v;
  }
  for (const int model : on) {
    const Block& b = blocks_.at(static_cast<std::size_t>(model));
    for (std::size_t k = 0; k < b.own.size(); ++k)
      params[b.own[k]] = physical_of(spec_of(b.space, b.own[k]), x(b.offset + 1 + static_cast<Eigen::Index>(k)));
  }
  return params;
}

namespace detail {

namespace {

// Emulator searches: random points scored, the best few refined by a compass search on the
// ensemble's mean predicted fitness.
constexpr int kRandomPoints = 256;
constexpr int kLocalStarts = 6;
constexpr double kFirstStep = 0.125, kLastStep = 1.0 / 512;
// A proposal closer than this (unit-cube distance over the model's coordinates) to a run of the
// model is not simulated again: the next best is taken.
constexpr double kSeparation = 1e-3;
// A candidate's further proposals of one round keep this far from its earlier ones (the pair
// search's first trust-region half-width): another valley of the emulator, not a neighbour of the
// first point, which the next round's emulator will have learnt about.
constexpr double kRoundSeparation = 0.1;
// Other targets of an effect that the pair search takes (DiagnosisRun::probed_targets), those whose
// best probes came closest: each adds a pair per partner, and a joint gap has eight targets.
constexpr std::size_t kOtherTargets = 2;

// A model of the union: its calibration space and cases (the archive's keys), and the model whose
// config simulates it (every case, the held-out ones included).
struct UnionModel {
  int index = -1;                           // UnionLayout's (-1: the base)
  EffectCandidate* candidate = nullptr;     // null for the base
  const ExtendedModel* extended = nullptr;  // null for the base
  // Another target of a candidate's effect (the pair search's, DiagnosisRun::probed_targets): its
  // best probe's set; null for a candidate at its own target, whose fit is its calibration's.
  const std::map<std::string, double>* other_target_fit = nullptr;
  CampaignConfig fitted;                    // the calibration's campaign: fitted cases, its space
  std::vector<ArchivedCase> cases;
};

struct Row {
  Eigen::VectorXd x;
  Eigen::VectorXd outputs;
  double fitness = 0;  // curve_fitness of the outputs: what the emulator's predictions are compared with
  std::vector<int> on;  // the models switched on (UnionLayout's indices; none: the base)
};

std::vector<ArchivedCase> archived_cases(const CampaignConfig& fitted, const std::vector<CaseCurveGrid>& grids) {
  std::vector<dem::Scene> scenes;
  for (std::size_t k = 0; k < fitted.cases.size(); ++k)
    scenes.push_back(build_scene(fitted.cases[k].scene, fitted.source + ": cases[" + std::to_string(k) + "].scene"));
  const ThreadBackend hashes(std::move(scenes), 1);
  std::vector<ArchivedCase> cases;
  for (std::size_t k = 0; k < fitted.cases.size(); ++k)
    cases.push_back({hashes.model_hash(k), grids[k].objective_key, fitted.cases[k].weight, grids[k].grid});
  return cases;
}

class Emulator {
 public:
  Emulator(std::vector<std::shared_ptr<const CurveGrid>> grids, surrogate::MlpOptions options)
      : grids_(std::move(grids)), options_(std::move(options)) {}

  // A full fit on `rows` the first time, then a continued one from the last weights.
  bool train(const std::vector<Row>& rows) {
    if (rows.empty()) return false;
    Eigen::MatrixXd X(static_cast<Eigen::Index>(rows.size()), rows.front().x.size());
    Eigen::MatrixXd Y(static_cast<Eigen::Index>(rows.size()), rows.front().outputs.size());
    for (std::size_t i = 0; i < rows.size(); ++i) {
      X.row(static_cast<Eigen::Index>(i)) = rows[i].x.transpose();
      Y.row(static_cast<Eigen::Index>(i)) = rows[i].outputs.transpose();
    }
    return ensemble_.fitted() ? ensemble_.refine(X, Y, options_) : ensemble_.fit(X, Y, options_);
  }

  // The members' mean fitness of their predicted curves at `x`.
  double fitness(const Eigen::VectorXd& x) const {
    double sum = 0;
    for (int m = 0; m < ensemble_.members(); ++m) sum += curve_fitness(ensemble_.predict(m, x), grids_);
    const double mean = sum / ensemble_.members();
    return std::isfinite(mean) ? mean : std::numeric_limits<double>::infinity();
  }

 private:
  std::vector<std::shared_ptr<const CurveGrid>> grids_;
  surrogate::MlpOptions options_;
  surrogate::CurveEnsemble ensemble_;
};

// Where a search of the emulator may go: per union coordinate, [lower, upper] within [0, 1].
struct Box {
  Eigen::VectorXd lower, upper;
  static Box whole(Eigen::Index dimension) {
    return {Eigen::VectorXd::Zero(dimension), Eigen::VectorXd::Ones(dimension)};
  }
};

// A compass search of `x` along `coordinates` on the emulator: each coordinate moved by ± step, the
// best move taken, the step halved when none improves; `value` is x's prediction, updated.
void compass_search(const Emulator& emulator, const std::vector<Eigen::Index>& coordinates, const Box& box,
                    Eigen::VectorXd& x, double& value) {
  for (double step = kFirstStep; step >= kLastStep;) {
    Eigen::VectorXd best = x;
    double best_value = value;
    for (const Eigen::Index k : coordinates)
      for (const double sign : {-1.0, 1.0}) {
        Eigen::VectorXd trial = x;
        trial(k) = std::clamp(trial(k) + sign * step, box.lower(k), box.upper(k));
        if (trial(k) == x(k)) continue;
        const double v = emulator.fitness(trial);
        if (v < best_value) {
          best_value = v;
          best = trial;
        }
      }
    if (best_value < value) {
      x = best;
      value = best_value;
    } else {
      step /= 2;
    }
  }
}

// Where the emulator puts the best point of the models `on` switched on together within `box`:
// random points over their coordinates and `starts` (clipped into the box) scored, the best
// kLocalStarts refined; the best refined point at least kSeparation from every point of `taken` (its
// runs and proposals so far). A further proposal of the round keeps kRoundSeparation from every
// point of `this_round` too, and where every refined point lies in their valleys it is the best
// scored point that does not. Empty when every point is taken.
Eigen::VectorXd propose(const Emulator& emulator, const UnionLayout& layout, const std::vector<int>& on,
                        const std::vector<Eigen::VectorXd>& starts, const std::vector<Eigen::VectorXd>& taken,
                        std::mt19937_64& rng, double& predicted, const Box& box,
                        const std::vector<Eigen::VectorXd>& this_round = {}) {
  const std::vector<Eigen::Index> coordinates = layout.coordinates(on);
  std::vector<std::pair<double, Eigen::VectorXd>> scored;
  for (const auto& s : starts) {
    Eigen::VectorXd x = layout.switched(on, s);
    x = x.cwiseMax(box.lower).cwiseMin(box.upper);
    scored.emplace_back(emulator.fitness(x), x);
  }
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  for (int i = 0; i < kRandomPoints; ++i) {
    Eigen::VectorXd x = layout.switched(on, starts.front());
    for (const Eigen::Index k : coordinates) x(k) = box.lower(k) + (box.upper(k) - box.lower(k)) * unit(rng);
    scored.emplace_back(emulator.fitness(x), x);
  }
  std::stable_sort(scored.begin(), scored.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  std::vector<std::pair<double, Eigen::VectorXd>> unrefined;
  if (!this_round.empty())
    unrefined.assign(std::make_move_iterator(scored.begin() + std::min<std::size_t>(scored.size(), kLocalStarts)),
                     std::make_move_iterator(scored.end()));
  scored.resize(std::min<std::size_t>(scored.size(), kLocalStarts));
  for (auto& [value, x] : scored) compass_search(emulator, coordinates, box, x, value);
  std::stable_sort(scored.begin(), scored.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  scored.insert(scored.end(), unrefined.begin(), unrefined.end());
  const auto distance = [&](const Eigen::VectorXd& a, const Eigen::VectorXd& b) {
    double sum = 0;
    for (const Eigen::Index k : coordinates) sum += (a(k) - b(k)) * (a(k) - b(k));
    return std::sqrt(sum);
  };
  const auto near = [&](const Eigen::VectorXd& x, const std::vector<Eigen::VectorXd>& points, double separation) {
    return std::any_of(points.begin(), points.end(), [&](const Eigen::VectorXd& t) { return distance(x, t) < separation; });
  };
  for (const auto& [value, x] : scored) {
    if (near(x, taken, kSeparation) || near(x, this_round, kRoundSeparation)) continue;
    predicted = value;
    return x;
  }
  return {};
}

// The outputs of a run's fitted cases (`fitted`'s names, in order) on their grids, as the archived
// runs' are read; empty when a case is missing, failed or has no curve on a channel.
Eigen::VectorXd fitted_outputs(const Evaluation& e, const CampaignConfig& fitted, const std::vector<ArchivedCase>& cases) {
  std::vector<RunCurves> runs;
  for (const auto& c : fitted.cases) {
    const auto it = std::find_if(e.cases.begin(), e.cases.end(), [&](const CasePrediction& p) { return p.name == c.name; });
    if (it == e.cases.end() || it->status == "failed") return {};
    runs.push_back({it->status, &it->simulated});
  }
  return run_outputs(runs, cases);
}

// The models of the union (the base and every calibrated candidate's), its layout, its rows (every
// archived run of those models on this step's objective grid) and its emulator.
struct Union {
  // `untried`: the effects probed in step 3 and not calibrated join too (at their best-signature
  // target, with no run yet), after the calibrated ones, then every other probed target of each
  // effect (DiagnosisRun::probed_targets).
  Union(DiagnosisRun& run, bool untried);

  CampaignConfig base_fitted;
  std::vector<CaseCurveGrid> case_grids;
  std::vector<std::shared_ptr<const CurveGrid>> grids;
  UnionLayout layout;
  std::vector<UnionModel> models;  // the base first
  std::vector<Row> rows;
  Emulator emulator;
  std::mt19937_64 rng;
  double model_s = 0;  // the emulator's fits and searches

  // `work` timed as model time.
  template <class Work>
  void model_time(Work&& work) {
    const auto start = std::chrono::steady_clock::now();
    work();
    model_s += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  }
  // The rows by fitness, best first.
  std::vector<const Row*> ranked() const {
    std::vector<const Row*> r;
    for (const auto& row : rows) r.push_back(&row);
    std::stable_sort(r.begin(), r.end(), [](const Row* a, const Row* b) { return a->fitness < b->fitness; });
    return r;
  }
  // Starts for the models `on` switched on together, at `fit` (the combination's best set so far):
  // `fit` and its own best runs, then the two best runs of every other model or combination with
  // the base parameters taken from them and the rest as in `fit` (what the others found about the
  // base parameters). Into `taken`: every run of the combination.
  std::vector<Eigen::VectorXd> starts(const std::vector<int>& on, const Eigen::VectorXd& fit,
                                      std::vector<Eigen::VectorXd>& taken) const;
  // The row of a run of the models `on` (its fitted cases' outputs as `fitted` and `cases` read
  // them); false when the run failed or lacks a curve.
  bool add_row(const Evaluation& e, const Eigen::VectorXd& x, const std::vector<int>& on, const CampaignConfig& fitted,
               const std::vector<ArchivedCase>& cases);
};

// The largest run id of each archive of `archives` (in order; -1 where it does not exist), as
// `search` (a key of DIR/union-horizons.json) first read them: written there on the search's first
// run, read back from there when the diagnosis is resumed (--resume) and the search had begun. In
// the archives' order, not by path, so that a resume naming the folder another way reads them too.
std::vector<std::int64_t> archive_horizons(const std::vector<std::string>& archives, const DiagnoseOptions& options,
                                           const std::string& search) {
  const fs::path file = fs::path(options.out) / "union-horizons.json";
  nlohmann::json written = nlohmann::json::object();
  if (fs::exists(file)) {
    std::ifstream in(file);
    written = nlohmann::json::parse(in, nullptr, false);
    if (!written.is_object()) written = nlohmann::json::object();  // cut short by a kill: taken anew
  }
  const auto& stored = written.contains(search) ? written[search] : nlohmann::json();
  if (options.resume && stored.is_array() && stored.size() == archives.size() &&
      std::all_of(stored.begin(), stored.end(), [](const nlohmann::json& id) { return id.is_number_integer(); }))
    return stored.get<std::vector<std::int64_t>>();
  std::vector<std::int64_t> horizons;
  for (const auto& path : archives) horizons.push_back(fs::exists(path) ? RunArchive(path).max_run_id() : -1);
  written[search] = horizons;
  std::ofstream(file) << written.dump(2) << '\n';
  return horizons;
}

std::vector<std::shared_ptr<const CurveGrid>> grid_pointers(const std::vector<CaseCurveGrid>& grids) {
  std::vector<std::shared_ptr<const CurveGrid>> pointers;
  for (const auto& g : grids) pointers.push_back(g.grid);
  return pointers;
}

surrogate::MlpOptions emulator_options(const DiagnosisRun& run) {
  surrogate::MlpOptions mlp = run.config.surrogate.options.mlp;
  mlp.seed = static_cast<std::uint64_t>(run.config.optimiser.seed);
  mlp.threads = std::max(1, hardware_threads());
  return mlp;
}

Union::Union(DiagnosisRun& run, bool untried)
    : base_fitted(fitted_cases(run.config, run.options)),
      case_grids(campaign_curve_grids(base_fitted)),
      grids(grid_pointers(case_grids)),
      layout(run.config.space),
      emulator(grids, emulator_options(run)),
      rng(static_cast<std::uint64_t>(run.config.optimiser.seed) * 0x9e3779b97f4a7c15ULL + 7) {
  models.resize(1);
  models.front().fitted = base_fitted;
  models.front().cases = archived_cases(base_fitted, case_grids);
  const auto add = [&](EffectCandidate& c, const ExtendedModel& extended, const std::map<std::string, double>* other_target_fit) {
    UnionModel m;
    m.candidate = &c;
    m.extended = &extended;
    m.other_target_fit = other_target_fit;
    m.fitted = fitted_cases(m.extended->config, run.options);
    m.fitted.space = extended_space(*m.extended, run.config, run.d.base_params, run.options);
    m.cases = archived_cases(m.fitted, case_grids);
    m.index = layout.add_model(m.fitted.space);
    models.push_back(std::move(m));
  };
  for (auto& c : run.d.candidates)
    if (c.tried && std::isfinite(c.error) && run.models.count(c.effect)) add(c, run.models.at(c.effect), nullptr);
  if (untried) {
    for (auto& c : run.d.candidates)
      if (!c.tried && run.models.count(c.effect) && run.warm_starts.count(c.effect)) add(c, run.models.at(c.effect), nullptr);
    // other probed targets of their effects, those whose best probes came closest first: a target
    // was chosen on the base fit, which may compensate for the effect sought
    const std::size_t candidates = models.size();
    for (std::size_t i = 1; i < candidates; ++i) {
      const auto probed = run.probed_targets.find(models[i].candidate->effect);
      if (probed == run.probed_targets.end()) continue;
      std::vector<ProbedTarget*> others;
      for (auto& t : probed->second)
        if (t.candidate.target != models[i].candidate->target) others.push_back(&t);
      std::stable_sort(others.begin(), others.end(),
                       [](const ProbedTarget* a, const ProbedTarget* b) { return a->warm_error < b->warm_error; });
      if (others.size() > kOtherTargets) others.resize(kOtherTargets);
      for (ProbedTarget* t : others) add(t->candidate, t->model, &t->warm);
    }
  }
  // Every archived run of the models, on the grids of this step's objective: a further step's base
  // model ran in the steps before it, whose archives come first. Only the runs archived when this
  // search first began: a resumed diagnosis reads the horizons that search wrote, so that runs the
  // stages after it made (a continued search, the removal check) do not train its emulator and it
  // makes the uninterrupted search again, its own rounds' runs read back from the archive.
  std::set<std::pair<int, std::vector<double>>> seen;
  std::vector<std::string> archives = run.earlier_archives;
  archives.push_back(diagnosis_archive(run.options));
  const std::vector<std::int64_t> horizons = archive_horizons(archives, run.options, untried ? "pair search" : "union search");
  for (std::size_t a = 0; a < archives.size(); ++a) {
    if (horizons[a] < 0 || !fs::exists(archives[a])) continue;
    const RunArchive archive(archives[a]);
    for (const auto& m : models)
      for (const auto& r : archive_training_rows(archive, m.fitted.space, m.cases, horizons[a])) {
        if (r.outputs.size() == 0 || !std::isfinite(r.fitness)) continue;
        const Eigen::VectorXd x = layout.point(m.index, m.fitted.space.values(m.fitted.space.to_physical(r.unit)));
        if (x.size() == 0 || !seen.insert({m.index, std::vector<double>(x.data(), x.data() + x.size())}).second) continue;
        rows.push_back({x, r.outputs, curve_fitness(r.outputs, grids), m.index < 0 ? std::vector<int>{} : std::vector<int>{m.index}});
      }
  }
}

std::vector<Eigen::VectorXd> Union::starts(const std::vector<int>& on, const Eigen::VectorXd& fit,
                                           std::vector<Eigen::VectorXd>& taken) const {
  const std::vector<const Row*> by_fitness = ranked();
  std::vector<Eigen::VectorXd> s = {fit};
  for (const Row* r : by_fitness)
    if (r->on == on) {
      taken.push_back(r->x);
      if (s.size() < 4) s.push_back(r->x);
    }
  std::map<std::vector<int>, int> added;
  for (const Row* r : by_fitness) {
    if (r->on == on || added[r->on] >= 2) continue;
    Eigen::VectorXd x = fit;
    x.head(layout.coordinates(-1).size()) = r->x.head(layout.coordinates(-1).size());
    s.push_back(x);
    ++added[r->on];
  }
  return s;
}

bool Union::add_row(const Evaluation& e, const Eigen::VectorXd& x, const std::vector<int>& on,
                    const CampaignConfig& fitted, const std::vector<ArchivedCase>& cases) {
  if (!e.ok) return false;
  const Eigen::VectorXd outputs = fitted_outputs(e, fitted, cases);
  if (outputs.size() == 0) return false;
  rows.push_back({x, outputs, curve_fitness(outputs, grids), on});
  return true;
}

}  // namespace

void search_union(DiagnosisRun& run) {
  const DiagnoseOptions& options = run.options;
  Union u(run, false);
  const auto& models = u.models;
  if (models.size() < 2) return;

  struct Best {
    double error = std::numeric_limits<double>::infinity();
    std::map<std::string, double> set;  // complete
  };
  std::vector<Best> best(models.size());
  std::vector<long> proposed(models.size(), 0);
  std::vector<int> rounds(models.size(), 0);
  // Points per candidate and round: every worker simulates, the candidates sharing them alike.
  const std::size_t candidates = models.size() - 1;
  const std::size_t per_candidate = std::max<std::size_t>(1, static_cast<std::size_t>(run.runner.workers()) / candidates);
  for (int round = 1; round <= options.union_rounds; ++round) {
    const long wanted = static_cast<long>(candidates * per_candidate) * static_cast<long>(models.front().cases.size());
    if (run.within_budget(wanted) < wanted) break;
    bool trained = false;
    u.model_time([&] { trained = u.emulator.train(u.rows); });
    if (!trained) break;
    std::vector<RunRequest> requests;
    std::vector<std::size_t> of_model;
    std::vector<Eigen::VectorXd> points;
    std::vector<std::map<std::string, double>> sets;
    for (std::size_t i = 1; i < models.size(); ++i) {
      const UnionModel& m = models[i];
      const Eigen::VectorXd fit = u.layout.point(m.index, run.best_sets.at(m.candidate->effect));
      if (fit.size() == 0) continue;
      std::vector<Eigen::VectorXd> taken;
      const std::vector<Eigen::VectorXd> starts = u.starts({m.index}, fit, taken);
      std::vector<Eigen::VectorXd> this_round;
      for (std::size_t k = 0; k < per_candidate; ++k) {
        double predicted = 0;
        Eigen::VectorXd x;
        u.model_time([&] {
          x = propose(u.emulator, u.layout, {m.index}, starts, taken, u.rng, predicted, Box::whole(u.layout.dimension()),
                      this_round);
        });
        if (x.size() == 0) break;
        this_round.push_back(x);
        const std::map<std::string, double> set = complete_parameters(m.fitted, u.layout.parameters(m.index, x));
        points.push_back(x);
        sets.push_back(set);
        of_model.push_back(i);
        requests.push_back({&m.extended->config, set, &run.base.residuals});
        progress(options, "union search, round " + std::to_string(round) + ": base + " + m.candidate->effect +
                              " predicted at fitness " + format_number(predicted, 4) + " by an emulator of " +
                              std::to_string(u.rows.size()) + " runs over " + std::to_string(u.layout.dimension()) +
                              " parameters");
      }
      if (!this_round.empty()) ++rounds[i];
    }
    if (requests.empty()) break;
    const std::vector<Evaluation> evaluations = run.runner.evaluate_all(requests);
    for (std::size_t j = 0; j < evaluations.size(); ++j) {
      const std::size_t i = of_model[j];
      const UnionModel& m = models[i];
      ++proposed[i];
      const Evaluation& e = evaluations[j];
      if (!e.ok) continue;
      u.add_row(e, points[j], {m.index}, m.fitted, m.cases);
      if (std::isfinite(e.error) && e.error < best[i].error) best[i] = {e.error, sets[j]};
      progress(options, "union search, round " + std::to_string(round) + ": base + " + m.candidate->effect +
                            " simulated, error " + format_number(e.error, 3) + " N (its calibration's " +
                            format_number(m.candidate->error, 3) + " N)");
    }
  }
  run.runner.add_model_seconds(u.model_s);

  // Each candidate's best proposal, judged as its calibration's fit is, where it ran below that fit.
  for (std::size_t i = 1; i < models.size(); ++i) {
    EffectCandidate& c = *models[i].candidate;
    UnionSearch& us = c.union_search;
    us.rounds = rounds[i];
    us.simulations = proposed[i];
    us.training_rows = static_cast<long>(u.rows.size());
    us.error_before = c.error;
    if (!(best[i].error < c.error)) {
      c.simulations += us.simulations;
      continue;
    }
    const std::vector<Evaluation> runs = runs_with_reruns(models[i].extended->config, models[i].fitted, best[i].set,
                                                          &run.base.residuals, options.scatter_runs, run.runner);
    us.simulations += static_cast<long>(runs.size());
    c.simulations += us.simulations;
    EffectCandidate judged = c;
    if (!judge_fit(judged, runs)) continue;
    us.error_found = judged.error;
    if (!(judged.error < c.error)) continue;
    us.kept = true;
    judged.union_search = us;
    judged.fitness = Diagnosis::kNaN;  // a direct run: the campaign's objective was not computed
    std::map<std::string, double> own;
    for (const auto& name : models[i].fitted.space.free_names()) own[name] = best[i].set.at(name);
    judged.params = own;
    c = std::move(judged);
    run.best_sets[c.effect] = best[i].set;
    progress(options, "union search: base + " + c.effect + " kept at " + format_number(c.error, 3) + " N (its calibration: " +
                          format_number(us.error_before, 3) + " N)");
  }
}

namespace {

// Pairs judged at most (those whose best run beats both of their effects' fits, lowest first): each
// costs its best set's runs and re-runs.
constexpr std::size_t kJudgedPairs = 3;
// A pair's trust region: its first, largest and least half-width in the unit cube.
constexpr double kFirstRadius = 0.1, kLargestRadius = 0.4, kLeastRadius = 1.0 / 64;

// A pair of the union's models and the model with both effects: the first's model extended by the
// second effect at its target, searched in the first's space and the second's own parameters.
struct PairModel {
  std::size_t first = 0, second = 0;  // Union::models indices
  std::vector<int> on;                 // their UnionLayout indices
  CampaignConfig with_first;           // the base model with the first effect, in its calibration's space
  ExtendedModel extended;
  CampaignConfig fitted;
  std::vector<ArchivedCase> cases;
  fs::path folder;  // its runs' and calibrations' folder
  double best_error = std::numeric_limits<double>::infinity();
  std::map<std::string, double> best_set;
  Eigen::VectorXd incumbent;  // the union point of best_set (empty: no run yet)
  double radius = kFirstRadius;
};

}  // namespace

namespace {

// An effect's fit: its calibration's best set, or for one not calibrated (or at another target) its
// best probe's set.
const std::map<std::string, double>& fit_of(const DiagnosisRun& run, const UnionModel& m) {
  if (m.other_target_fit != nullptr) return *m.other_target_fit;
  const auto found = run.best_sets.find(m.candidate->effect);
  return found != run.best_sets.end() ? found->second : run.warm_starts.at(m.candidate->effect);
}

// A model's name in the progress lines, and in its pair's folder: the effect, and the target where
// it is not the candidate's own.
std::string name_of(const UnionModel& m) {
  return m.candidate->effect + (m.other_target_fit != nullptr ? " at " + m.candidate->target : "");
}
std::string folder_of(const UnionModel& m) {
  return m.candidate->effect + (m.other_target_fit != nullptr ? "-at-" + file_safe(m.candidate->target) : "");
}
std::string name_of(const std::vector<UnionModel>& models, const PairModel& p) {
  return name_of(models[p.first]) + " + " + name_of(models[p.second]);
}

// The pairs on offer (Union::models indices): every pair of calibrated candidates, and the lead of
// the residual (the fit a tentative effect would start from) with every effect probed but not
// calibrated and every other target: the partner it would look for. The lead's target was chosen
// on a base fit that compensates, so its effect at its other targets is paired with every effect
// at its own too. Two targets of one effect are not paired.
std::vector<std::pair<std::size_t, std::size_t>> pairs_on_offer(const DiagnosisRun& run, const Union& u) {
  const auto& models = u.models;
  const EffectCandidate* lead = unexplained_lead(run.d, run.options);
  const auto own_target = [&](std::size_t i) { return models[i].other_target_fit == nullptr; };
  const auto lead_elsewhere = [&](std::size_t i) {
    return lead != nullptr && !own_target(i) && models[i].candidate->effect == lead->effect;
  };
  std::vector<std::pair<std::size_t, std::size_t>> chosen;
  for (std::size_t i = 1; i < models.size(); ++i)
    for (std::size_t j = i + 1; j < models.size(); ++j) {
      if (models[i].candidate->effect == models[j].candidate->effect) continue;
      const bool calibrated = models[i].candidate->tried && models[j].candidate->tried;
      const bool with_lead = models[i].candidate == lead || models[j].candidate == lead ||
                             (lead_elsewhere(i) && own_target(j)) || (lead_elsewhere(j) && own_target(i));
      if (calibrated || with_lead) chosen.emplace_back(i, j);
    }
  return chosen;
}

// Each pair's model: the first's model extended by the second effect at its target, its space the
// first's calibration's and the second's own parameters, started at the first's fit.
std::vector<PairModel> pair_models(const DiagnosisRun& run, const Union& u,
                                   const std::vector<std::pair<std::size_t, std::size_t>>& chosen) {
  const DiagnoseOptions& options = run.options;
  const auto& models = u.models;
  const dem::ResponseScales scales{std::isfinite(run.d.peak_normal_stress) ? run.d.peak_normal_stress : 0,
                                   std::isfinite(run.d.start_normal_stress) ? run.d.start_normal_stress : 0};
  std::vector<PairModel> pairs;
  for (const auto& [i, j] : chosen) {
    PairModel p;
    p.first = i;
    p.second = j;
    p.on = {models[i].index, models[j].index};
    const ExtendedModel& first = *models[i].extended;
    CampaignConfig& with_first = p.with_first;
    with_first = first.config;
    with_first.space = extended_space(first, run.config, run.d.base_params, options);
    const EffectCandidate& second = *models[j].candidate;
    const fs::path folder = fs::path(options.out) / "pairs" / (folder_of(models[i]) + "+" + folder_of(models[j]));
    p.extended = extend(with_first, dem::find_effect(second.effect),
                        second.target.empty() ? std::vector<std::string>{} : std::vector<std::string>{second.target},
                        scales, folder);
    p.folder = folder;
    p.fitted = fitted_cases(p.extended.config, options);
    p.fitted.space = extended_space(p.extended, with_first, fit_of(run, models[i]), options);
    p.cases = archived_cases(p.fitted, u.case_grids);
    pairs.push_back(std::move(p));
  }
  return pairs;
}

// The rounds. Round 1 simulates each pair where both effects' fits meet: one effect's best set with
// the other's own parameters at its fit, and the other way round. Each later round searches the
// emulator within a trust region around the pair's best run so far (a box of half-width `radius`
// in the unit cube, doubled after a round that improved on it, halved after one that did not; a
// pair whose region shrinks below kLeastRadius has converged and stops): an emulator searched over
// the whole space proposes where it is wrong, far from every run of the model with both. Every run
// joins the emulator's rows; each pair keeps its best run.
void search_pair_rounds(DiagnosisRun& run, Union& u, std::vector<PairModel>& pairs) {
  const DiagnoseOptions& options = run.options;
  const auto& models = u.models;
  for (int round = 1; round <= options.pair_rounds; ++round) {
    std::vector<RunRequest> requests;
    std::vector<std::size_t> of_pair;
    std::vector<Eigen::VectorXd> points;
    std::vector<std::map<std::string, double>> sets;
    const auto request = [&](std::size_t k, const Eigen::VectorXd& x) {
      const PairModel& p = pairs[k];
      points.push_back(x);
      sets.push_back(complete_parameters(p.fitted, u.layout.parameters(p.on, x)));
      of_pair.push_back(k);
      requests.push_back({&p.extended.config, sets.back(), &run.base.residuals});
    };
    if (round == 1) {
      for (std::size_t k = 0; k < pairs.size(); ++k) {
        const PairModel& p = pairs[k];
        const auto* first = &fit_of(run, models[p.first]);
        const auto* second = &fit_of(run, models[p.second]);
        const std::size_t before = points.size();
        for (const auto& [base, other] : {std::pair{first, second}, std::pair{second, first}}) {
          std::map<std::string, double> met = *other;           // the other's own parameters,
          for (const auto& [name, value] : *base) met[name] = value;  // the rest as in `base`
          const Eigen::VectorXd x = u.layout.point(p.on, met);
          if (x.size() > 0 && (points.size() == before || (points.back() - x).norm() > kSeparation)) request(k, x);
        }
      }
    } else {
      bool trained = false;
      u.model_time([&] { trained = u.emulator.train(u.rows); });
      if (!trained) break;
      for (std::size_t k = 0; k < pairs.size(); ++k) {
        const PairModel& p = pairs[k];
        if (p.incumbent.size() == 0 || p.radius < kLeastRadius) continue;
        Box box = Box::whole(u.layout.dimension());
        for (const Eigen::Index c : u.layout.coordinates(p.on)) {
          box.lower(c) = std::max(0.0, p.incumbent(c) - p.radius);
          box.upper(c) = std::min(1.0, p.incumbent(c) + p.radius);
        }
        std::vector<Eigen::VectorXd> taken;
        const std::vector<Eigen::VectorXd> starts = u.starts(p.on, p.incumbent, taken);
        double predicted = 0;
        Eigen::VectorXd x;
        u.model_time([&] { x = propose(u.emulator, u.layout, p.on, starts, taken, u.rng, predicted, box); });
        if (x.size() > 0) request(k, x);
      }
    }
    if (requests.empty() || run.within_budget(static_cast<long>(requests.size())) < static_cast<long>(requests.size())) break;
    run.d.pair_search.rounds = round;
    const std::vector<Evaluation> evaluations = run.runner.evaluate_all(requests);
    std::vector<bool> improved(pairs.size(), false);
    for (std::size_t r = 0; r < evaluations.size(); ++r) {
      PairModel& p = pairs[of_pair[r]];
      const Evaluation& e = evaluations[r];
      u.add_row(e, points[r], p.on, p.fitted, p.cases);
      if (e.ok && std::isfinite(e.error) && e.error < p.best_error) {
        p.best_error = e.error;
        p.best_set = sets[r];
        p.incumbent = points[r];
        improved[of_pair[r]] = true;
      }
    }
    if (round > 1)
      for (std::size_t k = 0; k < pairs.size(); ++k)
        if (std::find(of_pair.begin(), of_pair.end(), k) != of_pair.end())
          pairs[k].radius = improved[k] ? std::min(kLargestRadius, 2 * pairs[k].radius) : pairs[k].radius / 2;
    std::string line;
    for (const auto& p : pairs) line += (line.empty() ? "" : ", ") + name_of(models, p) + " " + format_number(p.best_error, 3) + " N";
    progress(options, "pair search, round " + std::to_string(round) + " (an emulator of " + std::to_string(u.rows.size()) +
                          " runs): best so far " + line);
  }
  run.runner.add_model_seconds(u.model_s);
}

// The closest pair calibrated as a candidate is, over the whole space of the model with both, its
// design starting at its best run: a few trust-region steps locate the pair's valley, a candidate's
// search budget reaches into it. The calibration minimises the campaign's objective, the judge is
// the force error: the best run is judged too where the calibration's fit is not below it, and the
// lower fit kept. Above the noise and scatter, its search is continued once from its fit, as a
// lead's is. False where no fit could be judged.
bool calibrate_closest_pair(DiagnosisRun& run, const Union& u, const PairModel& p, long budget, PairFit& f,
                            PairSearch::Pair& entry) {
  const DiagnoseOptions& options = run.options;
  const std::string pair = name_of(u.models, p);
  const fs::path folder = p.folder / "calibration";
  progress(options, "pair search: calibrating base + " + pair + " (" + std::to_string(budget) +
                        " simulations) from its best run (" + format_number(p.best_error, 3) + " N) in " + folder.string());
  try {
    calibrate_candidate(f.fit, f.set, p.extended, p.with_first, p.best_set, options, budget, folder, p.best_set,
                        run.base.residuals, run.runner);
  } catch (const std::exception& ex) {
    f.fit.reason = std::string("its calibration failed: ") + ex.what();
  }
  entry.calibrated = true;
  if (!(f.fit.error <= p.best_error)) {
    EffectCandidate at_best = f.fit;
    at_best.params = p.best_set;
    at_best.reason.clear();
    const std::vector<Evaluation> runs =
        runs_with_reruns(p.extended.config, p.fitted, p.best_set, &run.base.residuals, options.scatter_runs, run.runner);
    f.fit.simulations += static_cast<long>(runs.size());
    if (judge_fit(at_best, runs) && !(at_best.error >= f.fit.error)) {
      at_best.simulations = f.fit.simulations;
      f.fit = std::move(at_best);
      f.set = p.best_set;
    }
  }
  const long further = run.within_budget(run.continued_budget());
  if (f.fit.error > options.noise_level_ratio * floor_of(run.d, options) && further >= 2 * run.config.optimiser.population) {
    const fs::path continued = folder.parent_path() / "continued";
    progress(options, "pair search: " + pair + " stays at " + format_number(f.fit.error, 3) + " N: its search continued (" +
                          std::to_string(further) + " simulations) in " + continued.string());
    continue_search(f.fit, f.set, p.extended, p.with_first, f.set, options, further, continued, run.base.residuals,
                    run.runner, pair);
    entry.continued = true;
  }
  return std::isfinite(f.fit.error);
}

// Every pair's best run into the report; the pairs whose best run beats both of their effects'
// fits, lowest first (at most kJudgedPairs), judged on the median of their best set's runs, the
// first calibrated (calibrate_closest_pair) where the budget allows a candidate's search.
std::vector<PairFit> judge_pairs(DiagnosisRun& run, const Union& u, const std::vector<PairModel>& pairs) {
  const DiagnoseOptions& options = run.options;
  const auto& models = u.models;
  PairSearch& report = run.d.pair_search;
  std::vector<std::size_t> order;
  for (std::size_t k = 0; k < pairs.size(); ++k) {
    const PairModel& p = pairs[k];
    report.pairs.push_back({{models[p.first].candidate->effect, models[p.second].candidate->effect},
                            {models[p.first].candidate->target, models[p.second].candidate->target},
                            std::isfinite(p.best_error) ? p.best_error : PairSearch::kNaN});
    const auto beats = [&](const EffectCandidate& c) { return !c.tried || p.best_error < c.error; };
    if (std::isfinite(p.best_error) && beats(*models[p.first].candidate) && beats(*models[p.second].candidate))
      order.push_back(k);
  }
  std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return pairs[a].best_error < pairs[b].best_error; });
  if (order.size() > kJudgedPairs) order.resize(kJudgedPairs);
  std::vector<PairFit> fits;
  for (const std::size_t k : order) {
    const PairModel& p = pairs[k];
    PairFit f;
    f.pair = k;
    f.first = models[p.first].candidate;
    f.second = models[p.second].candidate;
    f.first_model = models[p.first].extended;
    f.second_model = models[p.second].extended;
    f.model = p.extended;
    f.set = p.best_set;
    f.fit.effect = f.second->effect;
    f.fit.target = f.second->target;
    f.fit.tried = true;
    f.fit.params = p.best_set;
    const long budget = run.within_budget(run.per_candidate);
    if (k == order.front() && budget >= 2 * run.config.optimiser.population) {
      if (!calibrate_closest_pair(run, u, p, budget, f, report.pairs[k])) continue;
    } else {
      const std::vector<Evaluation> runs =
          runs_with_reruns(p.extended.config, p.fitted, p.best_set, &run.base.residuals, options.scatter_runs, run.runner);
      if (!judge_fit(f.fit, runs)) continue;
    }
    f.fit.effect_parameters =
        static_cast<int>(f.first_model->parameter_names.size() + f.second_model->parameter_names.size());
    fits.push_back(std::move(f));
  }
  return fits;
}

}  // namespace

std::vector<PairFit> search_pairs(DiagnosisRun& run) {
  if (run.options.pair_rounds <= 0) return {};
  const long simulations_before = run.runner.simulations();
  Union u(run, true);
  std::vector<PairModel> pairs = pair_models(run, u, pairs_on_offer(run, u));
  if (pairs.empty()) return {};
  search_pair_rounds(run, u, pairs);
  std::vector<PairFit> fits = judge_pairs(run, u, pairs);
  run.d.pair_search.simulations = run.runner.simulations() - simulations_before;  // the calibrations' re-runs included
  return fits;
}

}  // namespace detail
}  // namespace demcal::pipelines
