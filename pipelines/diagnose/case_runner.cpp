// Runs of parameter sets for the diagnosis's stages (diagnose_internal.hpp): a set simulated on
// every case, its residuals on the base grid, re-runs that measure the simulation's own scatter.
#include "diagnose_internal.hpp"

#include "demcal/pipelines/backend.hpp"
#include "demcal/smoothing/objective.hpp"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <iostream>
#include <mutex>
#include <thread>

namespace demcal::pipelines::detail {

namespace fs = std::filesystem;

namespace {

// `best` with every free parameter of `config` moved by k x 1e-7 of itself: a set that differs from
// it by far less than anything physical (the scatter runs).
std::map<std::string, double> nudged(const std::map<std::string, double>& best, const CampaignConfig& config, int k) {
  auto moved = best;
  for (const auto& p : config.space.free_parameters()) moved[p.name] *= 1 + 1e-7 * k;
  return moved;
}

}  // namespace

std::string key_of(const ChannelResidual& c) { return c.case_name + "/" + c.channel; }

double overall_error(const std::vector<ChannelResidual>& residuals) {
  if (residuals.empty()) return Diagnosis::kNaN;
  double sum = 0;
  for (const auto& c : residuals) sum += c.rms * c.rms;
  return std::sqrt(sum / static_cast<double>(residuals.size()));
}

double overall(const std::map<std::string, double>& per_channel) {
  double sum = 0;
  int n = 0;
  for (const auto& [key, v] : per_channel)
    if (std::isfinite(v)) {
      sum += v * v;
      ++n;
    }
  return n ? std::sqrt(sum / n) : 0.0;
}

double overall_noise(const std::vector<ChannelResidual>& residuals) {
  double sum = 0;
  for (const auto& c : residuals) sum += c.noise * c.noise;
  return std::sqrt(sum / static_cast<double>(std::max<std::size_t>(1, residuals.size())));
}

void progress(const DiagnoseOptions& o, const std::string& line) {
  static std::mutex one_line_at_a_time;  // stages run side by side print whole lines
  if (!o.progress) return;
  const std::lock_guard lock(one_line_at_a_time);
  std::cerr << "diagnose: " + line + "\n" << std::flush;
}

bool is_held_out(const std::string& case_name, const std::vector<std::string>& held_out_cases) {
  return std::find(held_out_cases.begin(), held_out_cases.end(), case_name) != held_out_cases.end();
}

CaseRunner::CaseRunner(const CampaignConfig& config, const std::vector<std::string>& held_out_cases)
    : held_out_cases_(held_out_cases),
      workers_(config.backend.threads > 0 ? config.backend.threads : hardware_threads()) {
  for (const auto& c : config.cases) measured_.emplace(c.name, load_measured(c.measured));
}

Evaluation CaseRunner::evaluate(const CampaignConfig& config, const std::map<std::string, double>& params,
                                const std::vector<ChannelResidual>* grid) {
  return std::move(evaluate_all({{&config, params, grid}}).front());
}

std::vector<Evaluation> CaseRunner::evaluate_all(const std::vector<RunRequest>& requests) {
  auto simulated = simulate_all(requests);
  std::vector<Evaluation> out;
  for (std::size_t i = 0; i < requests.size(); ++i)
    out.push_back(score(*requests[i].config, std::move(simulated[i]), requests[i].grid));
  return out;
}

std::vector<std::vector<CasePrediction>> CaseRunner::simulate_all(const std::vector<RunRequest>& requests) {
  std::vector<std::vector<CasePrediction>> simulated(requests.size());
  std::vector<std::exception_ptr> errors(requests.size());
  const auto start = std::chrono::steady_clock::now();
  const int workers = std::max(1, std::min(workers_, static_cast<int>(requests.size())));
  PredictionOptions one_set;
  one_set.threads = requests.size() == 1 ? workers_ : 1;  // a lone set: its cases side by side
  std::atomic<std::size_t> next{0};
  const auto work = [&] {
    for (std::size_t i; (i = next++) < requests.size();) try {
        simulated[i] = predict_cases(*requests[i].config, requests[i].params, one_set);
      } catch (...) {
        errors[i] = std::current_exception();
      }
  };
  if (workers == 1) {
    work();
  } else {
    std::vector<std::thread> pool;
    for (int w = 0; w < workers; ++w) pool.emplace_back(work);
    for (auto& t : pool) t.join();
  }
  add_times(std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count(), 0);
  for (std::size_t i = 0; i < requests.size(); ++i) {
    if (errors[i]) std::rethrow_exception(errors[i]);
    const std::lock_guard lock(mutex_);
    simulations_ += static_cast<long>(simulated[i].size());
    simulated_this_session_ += static_cast<long>(simulated[i].size());
  }
  return simulated;
}

Evaluation CaseRunner::score(const CampaignConfig& config, std::vector<CasePrediction> cases,
                             const std::vector<ChannelResidual>* grid) const {
  Evaluation e;
  e.cases = std::move(cases);
  std::size_t g = 0;
  for (std::size_t k = 0; k < e.cases.size(); ++k) {
    const auto& p = e.cases[k];
    if (!p.ok()) {
      e.message = "case " + p.name + ": " + p.status + (p.message.empty() ? "" : " (" + p.message + ")");
      return e;
    }
    const auto found = measured_.find(p.name);
    if (found == measured_.end()) {
      e.message = "case " + p.name + " is not a case of the campaign";
      return e;
    }
    const smoothing::Curve& measured = found->second;
    const smoothing::Curve simulated = scored_curve(p.status, p.simulated, measured, config.objective_options);
    const auto channels = smoothing::common_channels(measured, simulated, config.objective_options);
    const bool case_held_out = is_held_out(p.name, held_out_cases_);
    for (const auto& ch : channels) {
      const auto weight = config.objective_options.channel_weights.find(ch);
      const auto sim = smoothing::series(simulated, ch, config.objective_options.force_column);
      if (case_held_out || (weight != config.objective_options.channel_weights.end() && weight->second == 0)) {
        // not fitted: a check of the fit, on its own grid
        try {
          ChannelResidual r = analyse_channel(smoothing::series(measured, ch, config.objective_options.force_column),
                                              sim, config.objective_options.points, config.objective_options.window);
          r.case_name = p.name;
          r.channel = ch;
          e.held_out.push_back(std::move(r));
        } catch (const smoothing::CurveError&) {
          // a held-out channel the simulation does not reach is left out of the check
        }
        continue;
      }
      ChannelResidual r;
      if (grid) {
        if (g >= grid->size()) {
          e.message = "the model's channels differ from the base model's";
          return e;
        }
        r = resimulated((*grid)[g++], sim);
      } else {
        r = analyse_channel(smoothing::series(measured, ch, config.objective_options.force_column), sim,
                            config.objective_options.points, config.objective_options.window);
      }
      r.case_name = p.name;
      r.channel = ch;
      e.residuals.push_back(std::move(r));
    }
  }
  e.ok = true;
  e.error = overall_error(e.residuals);
  if (!e.held_out.empty()) e.held_out_error = overall_error(e.held_out);
  return e;
}

void CaseRunner::add_runs_of(const CaseRunner& other) {
  simulations_ += other.simulations_;
  simulated_this_session_ += other.simulated_this_session_;
  simulation_s_ += other.simulation_s_;
  model_s_ += other.model_s_;
}

void CaseRunner::add_campaign(const CampaignResult& r) {
  {
    const std::lock_guard lock(mutex_);
    simulations_ += r.simulations;
    simulated_this_session_ += r.simulated_this_session;
  }
  add_times(r.simulation_time_s, r.model_time_s);
}

void CaseRunner::add_times(double simulation_s, double model_s) {
  const std::lock_guard lock(mutex_);
  (shared_ ? shared_simulation_s_ : simulation_s_) += simulation_s;
  (shared_ ? shared_model_s_ : model_s_) += model_s;
}

bool CaseRunner::runs_together(std::size_t tasks, bool together) const {
  // one worker: the tasks' runs one at a time; a task's own tasks: in its slot
  return together && workers_ > 1 && tasks > 1 && !shared_;
}

void CaseRunner::side_by_side(const std::vector<std::function<void()>>& tasks, bool together) {
  std::vector<std::exception_ptr> errors(tasks.size());
  const auto run = [&](std::size_t i) {
    try {
      tasks[i]();
    } catch (...) {
      errors[i] = std::current_exception();
    }
  };
  if (!runs_together(tasks.size(), together)) {
    for (std::size_t i = 0; i < tasks.size(); ++i) run(i);
  } else {
    const auto start = std::chrono::steady_clock::now();
    shared_ = true;
    std::atomic<std::size_t> next{0};
    std::vector<std::thread> pool;
    const int slots = std::min(kTasksPerWorker * workers_, static_cast<int>(tasks.size()));
    for (int w = 0; w < slots; ++w)
      pool.emplace_back([&] {
        for (std::size_t i; (i = next++) < tasks.size();) run(i);
      });
    for (auto& t : pool) t.join();
    shared_ = false;
    const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    const double spent = shared_simulation_s_ + shared_model_s_;
    const double model_share = spent > 0 ? shared_model_s_ / spent : 0;
    simulation_s_ += wall * (1 - model_share);
    model_s_ += wall * model_share;
    shared_simulation_s_ = shared_model_s_ = 0;
  }
  for (const auto& e : errors)
    if (e) std::rethrow_exception(e);
}

std::vector<double> stacked(const std::vector<ChannelResidual>& base, const std::vector<ChannelResidual>* other) {
  std::vector<double> v;
  for (std::size_t c = 0; c < base.size(); ++c) {
    const double scale = std::isfinite(base[c].noise) && base[c].noise > 0 ? 1 / base[c].noise : 1.0;
    for (std::size_t i = 0; i < base[c].measured.size(); ++i)
      v.push_back(scale * (other ? (*other)[c].simulated[i] - base[c].simulated[i]
                                 : base[c].measured[i] - base[c].simulated[i]));
  }
  return v;
}

std::vector<Evaluation> runs_with_reruns(const CampaignConfig& config, const CampaignConfig& nudge_space,
                                         const std::map<std::string, double>& params,
                                         const std::vector<ChannelResidual>* grid, int reruns, CaseRunner& runner) {
  std::vector<RunRequest> requests{{&config, params, grid}};
  for (int k = 1; k <= reruns; ++k) requests.push_back({&config, nudged(params, nudge_space, k), grid});
  auto simulated = runner.simulate_all(requests);
  std::vector<Evaluation> runs = {runner.score(config, std::move(simulated.front()), grid)};
  if (!runs.front().ok) return runs;
  const std::vector<ChannelResidual> on = grid ? *grid : runs.front().residuals;  // the re-runs on one grid
  for (int k = 1; k <= reruns; ++k) {
    Evaluation again = runner.score(config, std::move(simulated[static_cast<std::size_t>(k)]), &on);
    if (again.ok) runs.push_back(std::move(again));
  }
  return runs;
}

// The run of median error (of an even count, the worse middle one): a search keeps the luckiest run
// it meets, so a fit is judged on the middle of its run and re-runs.
const Evaluation& median_run(const std::vector<Evaluation>& runs) {
  std::vector<const Evaluation*> by_error;
  for (const auto& run : runs) by_error.push_back(&run);
  std::stable_sort(by_error.begin(), by_error.end(), [](const auto* a, const auto* b) { return a->error < b->error; });
  return *by_error[by_error.size() / 2];
}

// The simulation's own scatter per channel (into `per_channel`, "<case>/<channel>" -> N) and over
// all channels (returned; NaN with fewer than two runs): half the mean square difference of each
// pair of the runs' simulated curves (one set, re-run with its parameters moved by far less than
// anything physical, on one grid) estimates the variance of one curve.
double simulation_scatter(const std::vector<Evaluation>& runs, std::map<std::string, double>& per_channel) {
  if (runs.size() < 2) return Diagnosis::kNaN;
  const auto& first = runs.front().residuals;
  double total = 0;
  for (std::size_t c = 0; c < first.size(); ++c) {
    double sum = 0;
    int pairs = 0;
    for (std::size_t i = 0; i < runs.size(); ++i)
      for (std::size_t j = i + 1; j < runs.size(); ++j, ++pairs) {
        const auto& a = runs[i].residuals[c].simulated;
        const auto& b = runs[j].residuals[c].simulated;
        double sq = 0;
        for (std::size_t k = 0; k < a.size(); ++k) sq += (a[k] - b[k]) * (a[k] - b[k]);
        sum += sq / static_cast<double>(std::max<std::size_t>(1, a.size())) / 2;
      }
    const double variance = sum / pairs;
    per_channel[key_of(first[c])] = std::sqrt(variance);
    total += variance;
  }
  return std::sqrt(total / static_cast<double>(std::max<std::size_t>(1, first.size())));
}

std::string diagnosis_archive(const DiagnoseOptions& options) {
  return (fs::path(options.out) / "archive.sqlite").string();
}

CampaignConfig fitted_cases(CampaignConfig config, const DiagnoseOptions& options) {
  std::erase_if(config.cases, [&](const CaseSpec& c) { return is_held_out(c.name, options.held_out); });
  return config;
}

}  // namespace demcal::pipelines::detail
