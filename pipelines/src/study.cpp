#include "demcal/pipelines/study.hpp"

#include "demcal/pipelines/report.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <sstream>

namespace demcal::pipelines {

namespace fs = std::filesystem;
using nlohmann::json;

void StudyConfig::Validate() const {
  campaign.Validate();
  if (methods.empty()) throw CampaignError("study: no algorithms");
  if (seeds.empty()) throw CampaignError("study: no seeds");
  for (const auto& m : methods)
    if (m.iterations < 0) throw CampaignError("study: iterations of " + m.algorithm + " must be > 0");
}

StudyConfig load_study(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw CampaignError(path + ": cannot open the study file");
  json j;
  try {
    j = json::parse(in);
  } catch (const std::exception& e) {
    throw CampaignError(path + ": not valid JSON: " + e.what());
  }
  const std::string base = fs::path(path).parent_path().string();
  StudyConfig s;
  for (const auto& [key, value] : j.items())
    if (key != "campaign" && key != "algorithms" && key != "iterations" && key != "seeds" && key != "output")
      throw CampaignError(path + ": unknown key '" + key + "' (known: campaign, algorithms, iterations, seeds, output)");
  if (!j.contains("campaign")) throw CampaignError(path + ": missing 'campaign'");
  if (j["campaign"].is_string()) {
    const fs::path file = fs::path(base) / j["campaign"].get<std::string>();
    s.campaign = load_campaign(file.string());
  } else {
    s.campaign = campaign_from_json(j["campaign"], base, path + ": campaign");
  }
  if (!j.contains("algorithms") || !j["algorithms"].is_array())
    throw CampaignError(path + ": 'algorithms' must be an array of names");
  for (const auto& a : j["algorithms"]) {
    StudyMethod m;
    m.algorithm = a.get<std::string>();
    if (j.contains("iterations") && j["iterations"].contains(m.algorithm)) m.iterations = j["iterations"][m.algorithm].get<int>();
    s.methods.push_back(m);
  }
  if (j.contains("seeds")) {
    if (j["seeds"].is_array()) {
      for (const auto& seed : j["seeds"]) s.seeds.push_back(seed.get<std::uint64_t>());
    } else {
      const auto first = j["seeds"].value("first", 1ull);
      const auto count = j["seeds"].value("count", 10ull);
      for (std::uint64_t i = 0; i < count; ++i) s.seeds.push_back(first + i);
    }
  } else {
    for (std::uint64_t i = 1; i <= 10; ++i) s.seeds.push_back(i);
  }
  s.output = (fs::path(base) / j.value("output", std::string("study"))).lexically_normal().string();
  return s;
}

StudyResult run_study(const StudyConfig& config, bool progress) {
  config.Validate();
  fs::create_directories(config.output);
  StudyResult result;
  json out = json::array();
  std::map<std::string, std::vector<std::vector<double>>> convergence;  // method -> per-seed history
  for (const auto& method : config.methods) {
    StudyMethodResult r;
    r.method = method;
    const int iterations = method.iterations > 0 ? method.iterations : config.campaign.optimiser.iterations;
    r.method.iterations = iterations;
    const std::string label = method.algorithm + "-" + std::to_string(iterations);
    std::string safe = label;
    std::replace(safe.begin(), safe.end(), ':', '_');
    for (const auto seed : config.seeds) {
      CampaignConfig c = config.campaign;
      c.optimiser.algorithm = method.algorithm;
      c.optimiser.iterations = iterations;
      c.optimiser.seed = seed;
      c.output = (fs::path(config.output) / safe / ("seed-" + std::to_string(seed))).string();
      c.archive = (fs::path(config.output) / "archive.sqlite").string();
      c.report = false;
      RunOptions options;
      options.progress = false;
      const CampaignResult campaign = run_campaign(c, options);
      ParameterSet best = campaign.best;
      r.best_per_seed.push_back(best);
      r.seeds.push_back(seed);
      r.simulations = campaign.simulations;
      r.wall_time_s += campaign.wall_time_s;
      convergence[label].push_back(campaign.best_history);
      if (progress)
        std::cerr << label << " seed " << seed << ": best " << best.fitness << " (" << campaign.simulations
                  << " simulations, " << campaign.wall_time_s << " s)\n";
    }
    std::vector<double> values;
    for (const auto& b : r.best_per_seed)
      if (std::isfinite(b.fitness)) values.push_back(b.fitness);
    std::vector<size_t> order(r.best_per_seed.size());
    for (size_t i = 0; i < order.size(); ++i) order[i] = i;
    std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) {
      const double fa = r.best_per_seed[a].fitness, fb = r.best_per_seed[b].fitness;
      return (std::isfinite(fa) ? fa : INFINITY) < (std::isfinite(fb) ? fb : INFINITY);
    });
    for (size_t i = 0; i < order.size() && i < 5; ++i) r.five_best.push_back(r.best_per_seed[order[i]]);
    if (!values.empty()) {
      std::sort(values.begin(), values.end());
      double sum = 0, sq = 0;
      for (double v : values) sum += v, sq += v * v;
      r.mean = sum / values.size();
      r.stddev = values.size() > 1 ? std::sqrt(std::max(0.0, (sq - values.size() * r.mean * r.mean) / (values.size() - 1))) : 0;
      r.min = values.front();
      r.max = values.back();
      r.median = values.size() % 2 ? values[values.size() / 2]
                                   : 0.5 * (values[values.size() / 2 - 1] + values[values.size() / 2]);
    }
    json seeds = json::array();
    for (size_t i = 0; i < r.seeds.size(); ++i)
      seeds.push_back({{"seed", r.seeds[i]}, {"params", r.best_per_seed[i].params},
                       {"fitness", std::isfinite(r.best_per_seed[i].fitness) ? json(r.best_per_seed[i].fitness) : json(nullptr)}});
    out.push_back({{"algorithm", method.algorithm}, {"iterations", iterations}, {"runs", seeds},
                   {"fitness", {{"mean", r.mean}, {"stddev", r.stddev}, {"median", r.median}, {"min", r.min}, {"max", r.max}}},
                   {"simulations_per_campaign", r.simulations}, {"wall_time_s", r.wall_time_s}});
    result.methods.push_back(r);
  }
  std::ofstream(fs::path(config.output) / "study.json") << json{{"methods", out}}.dump(2) << "\n";

  // study.md: the paper's Tables 1-4 layout, then the statistics and a convergence figure.
  std::ostringstream md;
  const auto free = config.campaign.space.free_names();
  md << "# Study: " << config.campaign.name << "\n\n" << config.seeds.size() << " seeds per method, objective "
     << config.campaign.objective << ", population " << config.campaign.optimiser.population << ".\n\n";
  md << "## Five best solution sets per method\n\n| Calibration process | Number of iterations | Run ID |";
  for (const auto& n : free) md << " " << n << " |";
  md << " Fitness (-) |\n| --- | --- | --- |";
  for (size_t i = 0; i < free.size(); ++i) md << " --- |";
  md << " --- |\n";
  auto cell = [](const std::string& name, double v) {
    char b[32];
    const bool stiffness = name == "kn" || name == "ks" || name.ends_with(".kn") || name.ends_with(".ks");
    std::snprintf(b, sizeof b, stiffness ? "%.3g GPa/m" : "%.2f", stiffness ? v / 1e9 : v);
    return std::string(b);
  };
  for (const auto& r : result.methods)
    for (size_t i = 0; i < r.five_best.size(); ++i) {
      md << "| " << (i == 0 ? r.method.algorithm : "") << " | " << (i == 0 ? std::to_string(r.method.iterations) : "")
         << " | " << i + 1 << " |";
      for (const auto& n : free) md << " " << (r.five_best[i].params.count(n) ? cell(n, r.five_best[i].params.at(n)) : "-") << " |";
      char f[32];
      std::snprintf(f, sizeof f, "%.1f", r.five_best[i].fitness);
      md << " " << f << " |\n";
    }
  md << "\n## Fitness of the best set per seed\n\n| method | iterations | simulations per campaign | mean | std | median | min | max | wall time (s) |\n"
     << "| --- | --- | --- | --- | --- | --- | --- | --- | --- |\n";
  for (const auto& r : result.methods) {
    char line[320];
    std::snprintf(line, sizeof line, "| %s | %d | %ld | %.2f | %.2f | %.2f | %.2f | %.2f | %.1f |\n",
                  r.method.algorithm.c_str(), r.method.iterations, r.simulations, r.mean, r.stddev, r.median, r.min,
                  r.max, r.wall_time_s);
    md << line;
  }
  // Mean of the per-seed best-so-far curves against simulations.
  std::string script, plot = "set xlabel 'simulations'\nset ylabel 'mean best fitness over seeds'\nset logscale y\nset grid\nplot ";
  int block = 0;
  for (const auto& [label, histories] : convergence) {
    size_t n = 0;
    for (const auto& h : histories) n = std::max(n, h.size());
    script += "$c" + std::to_string(block) + " << EOD\n";
    for (size_t i = 0; i < n; ++i) {
      double sum = 0;
      int count = 0;
      for (const auto& h : histories)
        if (i < h.size() && std::isfinite(h[i])) sum += h[i], ++count;
      if (count) script += std::to_string((i + 1) * config.campaign.cases.size()) + " " + std::to_string(sum / count) + "\n";
    }
    script += "EOD\n";
    plot += std::string(block ? ", " : "") + "$c" + std::to_string(block) + " using 1:2 with lines lw 2 title '" + label + "'";
    ++block;
  }
  fs::create_directories(fs::path(config.output) / "figures");
  const std::string error = run_gnuplot(script + plot + "\n", (fs::path(config.output) / "figures" / "convergence.png").string());
  md << "\n## Convergence\n\n"
     << (error.empty() ? "![mean best fitness against simulations](figures/convergence.png)\n" : "*Figure not drawn: " + error + "*\n");
  std::ofstream(fs::path(config.output) / "study.md") << md.str();
  return result;
}

}  // namespace demcal::pipelines
