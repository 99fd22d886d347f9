#include "demcal/pipelines/study.hpp"

#include "demcal/common/format.hpp"
#include "demcal/limits/limits.hpp"
#include "demcal/pipelines/report.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <set>
#include <sstream>

namespace demcal::pipelines {

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

std::string method_label(const StudyMethod& m, int iterations) {
  return m.label.empty() ? m.algorithm + "-" + std::to_string(iterations) : m.label;
}

// A folder name from a label ("nlopt:GN_ISRES-20" -> "nlopt_GN_ISRES-20").
std::string folder_name(std::string label) {
  for (char& c : label)
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '-' || c == '_' || c == '.')) c = '_';
  return label;
}

bool is_stiffness(const std::string& name) {
  return name == "kn" || name == "ks" || name.ends_with(".kn") || name.ends_with(".ks");
}

// Column header and display value of a parameter (stiffness in GPa/m, friction in degrees).
std::string header_of(const std::string& name) {
  if (is_stiffness(name)) return name + " (GPa/m)";
  if (name == "friction_deg" || name.ends_with(".friction_deg")) return name + " (deg)";
  return name;
}
double display_value(const std::string& name, double v) { return is_stiffness(name) ? v / 1e9 : v; }

// Numbers in tables and gnuplot scripts; NaN and +/-inf are "-".
constexpr NumberFormat three_digits{.significant_digits = 3, .non_finite = "-"};
constexpr NumberFormat six_digits{.significant_digits = 6, .non_finite = "-"};
constexpr NumberFormat ten_digits{.significant_digits = 10, .non_finite = "-"};
constexpr NumberFormat one_decimal{.fixed_decimals = 1, .non_finite = "-"};
constexpr NumberFormat two_decimals{.fixed_decimals = 2, .non_finite = "-"};

json statistics_json(const FitnessStatistics& s) {
  return {{"count", s.count}, {"mean", s.mean}, {"stddev", s.stddev}, {"median", s.median}, {"min", s.min}, {"max", s.max}};
}

// Best fitness after `simulations` simulations of a campaign (NaN when it has no finite value yet).
double best_after(const StudyCampaign& c, long simulations, size_t cases) {
  if (c.best_history.empty() || simulations <= 0) return NAN;
  const size_t candidates = static_cast<size_t>(simulations) / std::max<size_t>(1, cases);
  if (candidates == 0) return NAN;
  return c.best_history[std::min(candidates, c.best_history.size()) - 1];
}

}  // namespace

FitnessStatistics fitness_statistics(std::vector<double> values) {
  values.erase(std::remove_if(values.begin(), values.end(), [](double v) { return !std::isfinite(v); }), values.end());
  FitnessStatistics s;
  s.count = static_cast<long>(values.size());
  if (values.empty()) return s;
  std::sort(values.begin(), values.end());
  double sum = 0;
  for (double v : values) sum += v;
  s.mean = sum / values.size();
  double sq = 0;
  for (double v : values) sq += (v - s.mean) * (v - s.mean);
  s.stddev = values.size() > 1 ? std::sqrt(sq / (values.size() - 1)) : 0;
  s.min = values.front();
  s.max = values.back();
  const size_t n = values.size();
  s.median = n % 2 ? values[n / 2] : 0.5 * (values[n / 2 - 1] + values[n / 2]);
  return s;
}

void StudyConfig::Validate() const {
  campaign.Validate();
  if (methods.empty()) throw CampaignError(source + ": no algorithms");
  if (seeds.empty()) throw CampaignError(source + ": no seeds");
  if (auto m = limits::check(limits::Limit::campaigns, static_cast<double>(methods.size()) * seeds.size()))
    throw CampaignError(source + ": " + std::to_string(methods.size()) + " methods x " + std::to_string(seeds.size()) +
                        " seeds: " + *m);
  std::set<std::uint64_t> seen_seeds;
  for (const auto seed : seeds)
    if (!seen_seeds.insert(seed).second) throw CampaignError(source + ": seed " + std::to_string(seed) + " is listed twice");
  std::set<std::string> labels;
  for (size_t i = 0; i < methods.size(); ++i) {
    const auto& m = methods[i];
    const std::string where = source + ": algorithms[" + std::to_string(i) + "] ('" + m.algorithm + "')";
    if (m.iterations < 0)
      throw CampaignError(where + ": iterations = " + std::to_string(m.iterations) + " must be >= 1 (or 0 = the campaign's)");
    optimise::OptimiserOptions o = campaign.optimiser;
    o.algorithm = m.algorithm;
    if (m.iterations > 0) o.iterations = m.iterations;
    try {
      o.Validate();
    } catch (const std::exception& e) {
      throw CampaignError(where + ": " + e.what());
    }
    const std::string label = method_label(m, o.iterations);
    if (!labels.insert(label).second)
      throw CampaignError(where + ": label '" + label + "' is used twice (give the methods distinct labels)");
  }
}

StudyConfig study_from_json(const json& j, const std::string& base, const std::string& path) {
  if (!j.is_object()) throw CampaignError(path + ": a study must be a JSON object");
  for (const auto& [key, value] : j.items())
    if (key != "campaign" && key != "algorithms" && key != "iterations" && key != "seeds" && key != "output" &&
        key != "description")
      throw CampaignError(path + ": unknown key '" + key +
                          "' (known: campaign, algorithms, iterations, seeds, output, description)");
  StudyConfig s;
  if (!j.contains("campaign")) throw CampaignError(path + ": missing 'campaign'");
  if (j["campaign"].is_string()) {
    const fs::path file = fs::path(base) / j["campaign"].get<std::string>();
    s.campaign = load_campaign(file.string());
  } else if (j["campaign"].is_object()) {
    s.campaign = campaign_from_json(j["campaign"], base, path + ": campaign");
  } else {
    throw CampaignError(path + ": 'campaign' must be a file name or a campaign object, not " + j["campaign"].dump());
  }
  if (j.contains("iterations") && !j["iterations"].is_object())
    throw CampaignError(path + ": 'iterations' must be an object {algorithm: iterations}, not " + j["iterations"].dump());
  auto integer = [&](const json& v, const std::string& key) {
    if (!v.is_number_integer()) throw CampaignError(path + ": " + key + " must be an integer, not " + v.dump());
    return v.get<long long>();
  };
  if (!j.contains("algorithms") || !j["algorithms"].is_array() || j["algorithms"].empty())
    throw CampaignError(path + ": 'algorithms' must be a non-empty array of names or {algorithm, iterations, label}");
  for (size_t i = 0; i < j["algorithms"].size(); ++i) {
    const json& a = j["algorithms"][i];
    const std::string key = "algorithms[" + std::to_string(i) + "]";
    StudyMethod m;
    if (a.is_string()) {
      m.algorithm = a.get<std::string>();
      if (j.contains("iterations") && j["iterations"].contains(m.algorithm))
        m.iterations = static_cast<int>(integer(j["iterations"][m.algorithm], "iterations." + m.algorithm));
    } else if (a.is_object()) {
      for (const auto& [k, v] : a.items())
        if (k != "algorithm" && k != "iterations" && k != "label")
          throw CampaignError(path + ": " + key + ": unknown key '" + k + "' (known: algorithm, iterations, label)");
      if (!a.contains("algorithm") || !a["algorithm"].is_string())
        throw CampaignError(path + ": " + key + ": 'algorithm' (a name) is missing");
      m.algorithm = a["algorithm"].get<std::string>();
      if (a.contains("iterations")) m.iterations = static_cast<int>(integer(a["iterations"], key + ".iterations"));
      else if (j.contains("iterations") && j["iterations"].contains(m.algorithm))
        m.iterations = static_cast<int>(integer(j["iterations"][m.algorithm], "iterations." + m.algorithm));
      if (a.contains("label")) {
        if (!a["label"].is_string() || a["label"].get<std::string>().empty())
          throw CampaignError(path + ": " + key + ".label must be a non-empty string, not " + a["label"].dump());
        m.label = a["label"].get<std::string>();
      }
    } else {
      throw CampaignError(path + ": " + key + " must be a name or an object, not " + a.dump());
    }
    s.methods.push_back(m);
  }
  if (j.contains("seeds")) {
    const json& seeds = j["seeds"];
    auto seed_value = [&](const json& v, const std::string& key) {
      if (!v.is_number_integer() || v.get<long long>() < 0)
        throw CampaignError(path + ": " + key + " must be a non-negative integer, not " + v.dump());
      return v.get<std::uint64_t>();
    };
    if (seeds.is_array()) {
      for (size_t i = 0; i < seeds.size(); ++i) s.seeds.push_back(seed_value(seeds[i], "seeds[" + std::to_string(i) + "]"));
    } else if (seeds.is_object()) {
      for (const auto& [k, v] : seeds.items())
        if (k != "first" && k != "count") throw CampaignError(path + ": seeds: unknown key '" + k + "' (known: first, count)");
      const std::uint64_t first = seeds.contains("first") ? seed_value(seeds["first"], "seeds.first") : 1;
      const std::uint64_t count = seeds.contains("count") ? seed_value(seeds["count"], "seeds.count") : 10;
      if (count < 1) throw CampaignError(path + ": seeds.count = 0 must be >= 1");
      for (std::uint64_t i = 0; i < count; ++i) s.seeds.push_back(first + i);
    } else {
      throw CampaignError(path + ": 'seeds' must be an array or {first, count}, not " + seeds.dump());
    }
  } else {
    for (std::uint64_t i = 1; i <= 10; ++i) s.seeds.push_back(i);
  }
  if (j.contains("output") && !j["output"].is_string())
    throw CampaignError(path + ": 'output' must be a folder name, not " + j["output"].dump());
  s.output = (fs::path(base) / j.value("output", std::string("study"))).lexically_normal().string();
  s.source = path;
  s.Validate();
  return s;
}

StudyConfig load_study(const std::string& path) {
  if (auto m = limits::check_file_size(path)) throw CampaignError(path + ": " + *m);
  std::ifstream in(path);
  if (!in) throw CampaignError(path + ": cannot open the study file");
  json j;
  try {
    j = json::parse(in);
  } catch (const std::exception& e) {
    throw CampaignError(path + ": not valid JSON: " + e.what());
  }
  return study_from_json(j, fs::path(path).parent_path().string(), path);
}

namespace {

using optimise::ParameterSpec;

void write_study_summary(std::ostream& md, const StudyConfig& config) {
  md << "# Study: " << config.campaign.name << "\n\n"
     << config.methods.size() << " methods x " << config.seeds.size() << " seeds (";
  for (size_t i = 0; i < config.seeds.size(); ++i) md << (i ? ", " : "") << config.seeds[i];
  md << "), objective " << config.campaign.objective << ", population " << config.campaign.optimiser.population
     << ", " << config.campaign.cases.size()
     << " case(s) per candidate. Every campaign's result is in `<method>/seed-<seed>/result.json`.\n";
}

// One row of the five-best table: the method's per-seed best set ranked `rank` (0 = best).
void write_five_best_row(std::ostream& md, const StudyConfig& config, const StudyMethodResult& r, size_t rank) {
  const auto& free = config.campaign.space.free_parameters();
  const StudyCampaign& c = r.campaigns[r.five_best[rank]];
  md << "| " << (rank == 0 ? r.method.label : "") << " | " << (rank == 0 ? std::to_string(r.method.iterations) : "")
     << " | " << rank + 1 << " |";
  for (const auto& p : free) {
    const NumberFormat& shown = is_stiffness(p.name) ? three_digits : two_decimals;
    md << " " << (c.best.params.count(p.name) ? format_number(display_value(p.name, c.best.params.at(p.name)), shown) : "-")
       << " |";
  }
  const auto hit = std::find(c.best_history.begin(), c.best_history.end(), c.best.fitness);
  const long found = static_cast<long>(hit - c.best_history.begin()) + 1;
  const long cases = static_cast<long>(config.campaign.cases.size());
  md << " " << format_number(c.best.fitness, one_decimal) << " | " << c.seed << " | "
     << (std::isfinite(c.best.fitness) ? std::to_string(found * cases) : "-") << " |\n";
}

// The paper's Tables 1-4: per method, the five best of the per-seed best sets.
void write_five_best(std::ostream& md, const StudyConfig& config, const StudyResult& result) {
  const auto& free = config.campaign.space.free_parameters();
  md << "\n## Five best solution sets per method\n\nThe best set of each seed's campaign; the five best of them per "
        "method (Run ID = rank).\n\n| Calibration process | Number of iterations | Run ID |";
  for (const auto& p : free) md << " " << header_of(p.name) << " |";
  md << " Fitness (-) | seed | found at simulation |\n|---|---|---|";
  for (size_t i = 0; i < free.size(); ++i) md << "---|";
  md << "---|---|---|\n";
  for (const auto& r : result.methods)
    for (size_t rank = 0; rank < r.five_best.size(); ++rank) write_five_best_row(md, config, r, rank);
}

// "mean | std | median | min | max" of a table row.
std::string statistics_cells(const FitnessStatistics& s) {
  return format_number(s.mean, one_decimal) + " | " + format_number(s.stddev, one_decimal) + " | " + format_number(s.median, one_decimal) + " | " +
         format_number(s.min, one_decimal) + " | " + format_number(s.max, one_decimal);
}

void write_fitness_tables(std::ostream& md, const StudyResult& result) {
  md << "\n## Fitness of the best set per seed\n\n| method | iterations | seeds with a result | mean | std | median | min | max |\n"
     << "|---|---|---|---|---|---|---|---|\n";
  for (const auto& r : result.methods)
    md << "| " << r.method.label << " | " << r.method.iterations << " | " << r.fitness.count << "/"
       << r.campaigns.size() << " | " << statistics_cells(r.fitness) << " |\n";
  md << "\n## At equal cost: best fitness after " << result.common_budget
     << " simulations\n\nThe per-seed best after the fewest simulations any method used, so that methods with "
        "larger budgets are compared at the same cost.\n\n| method | mean | std | median | min | max |\n|---|---|---|---|---|---|\n";
  for (const auto& r : result.methods)
    md << "| " << r.method.label << " | " << statistics_cells(r.fitness_at_common_budget) << " |\n";
}

void write_simulations_used(std::ostream& md, const StudyResult& result) {
  md << "\n## Simulations used\n\n| method | per campaign | all seeds | simulated in this session (rest read from the "
        "archive) | wall time this session (s) |\n|---|---|---|---|---|\n";
  for (const auto& r : result.methods) {
    long simulated = 0;
    for (const auto& c : r.campaigns) simulated += c.simulated;
    md << "| " << r.method.label << " | " << r.simulations_per_campaign << " | " << r.simulations_total << " | "
       << simulated << " | " << format_number(r.wall_time_s, one_decimal) << " |\n";
  }
}

void write_failed_campaigns(std::ostream& md, const StudyResult& result) {
  bool any_failed = false;
  for (const auto& r : result.methods)
    for (const auto& c : r.campaigns)
      if (c.status != CampaignStatus::completed) {
        if (!any_failed) md << "\n## Failed campaigns\n\n";
        any_failed = true;
        md << "- " << r.method.label << " seed " << c.seed << ": " << c.message << "\n";
      }
}

// Gnuplot datablock $c<m>: the best fitness so far, mean over the method's seeds, against
// simulations. `positive` turns false where a mean is not above 0 (no log scale then).
std::string mean_best_datablock(const StudyMethodResult& r, size_t m, size_t cases, bool& positive) {
  size_t n = 0;
  for (const auto& c : r.campaigns) n = std::max(n, c.best_history.size());
  std::string block = "$c" + std::to_string(m) + " << EOD\n";
  for (size_t i = 0; i < n; ++i) {
    double sum = 0;
    int count = 0;
    for (const auto& c : r.campaigns)
      if (i < c.best_history.size() && std::isfinite(c.best_history[i])) sum += c.best_history[i], ++count;
    if (count == 0) continue;
    if (sum <= 0) positive = false;
    block += std::to_string((i + 1) * cases) + " " + format_number(sum / count, ten_digits) + "\n";
  }
  return block + "EOD\n";
}

void write_convergence_figure(std::ostream& md, const StudyConfig& config, const StudyResult& result) {
  std::string script, plot;
  bool positive = true;
  for (size_t m = 0; m < result.methods.size(); ++m) {
    script += mean_best_datablock(result.methods[m], m, config.campaign.cases.size(), positive);
    plot += std::string(m ? ", " : "") + "$c" + std::to_string(m) + " using 1:2 with lines lw 2 title '" +
            result.methods[m].method.label + "'";
  }
  script += "set xlabel 'simulations'\nset ylabel 'best fitness, mean over seeds'\nset grid\nset key top right\n";
  if (positive) script += "set logscale y\n";
  const std::string convergence_error =
      run_gnuplot(script + "plot " + plot + "\n", (fs::path(config.output) / "figures" / "convergence.png").string());
  md << "\n## Convergence\n\n"
     << (convergence_error.empty() ? "![mean best fitness against simulations](figures/convergence.png)\n"
                                   : "*Figure not drawn: " + convergence_error + "*\n");
}

// "set xrange [lower:upper]" over a parameter's range, in display units.
std::string axis_range(char axis, const ParameterSpec& p) {
  return std::string("set ") + axis + "range [" + format_number(display_value(p.name, p.lower), ten_digits) + ":" +
         format_number(display_value(p.name, p.upper), ten_digits) + "]\n";
}

// The per-seed best sets of every method, `x` against `y`; returns the figure's markdown.
std::string positions_figure(const StudyConfig& config, const StudyResult& result, const ParameterSpec& x,
                             const ParameterSpec& y) {
  static const char* colours[] = {"#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#17becf", "#7f7f7f"};
  std::string s, p;
  for (size_t m = 0; m < result.methods.size(); ++m) {
    s += "$m" + std::to_string(m) + " << EOD\n";
    for (const auto& c : result.methods[m].campaigns)
      if (std::isfinite(c.best.fitness))
        s += format_number(display_value(x.name, c.best.params.at(x.name)), ten_digits) + " " +
             format_number(display_value(y.name, c.best.params.at(y.name)), ten_digits) + "\n";
    s += "EOD\n";
    p += std::string(m ? ", " : "") + "$m" + std::to_string(m) + " using 1:2 with points pt " + std::to_string(5 + 2 * (m % 4)) +
         " ps 1.6 lc rgb '" + colours[m % 8] + "' title '" + result.methods[m].method.label + "'";
  }
  s += "set xlabel '" + header_of(x.name) + "'\nset ylabel '" + header_of(y.name) + "'\n";
  s += axis_range('x', x) + axis_range('y', y);
  if (x.scale == ParameterSpec::Scale::log10) s += "set logscale x\n";
  if (y.scale == ParameterSpec::Scale::log10) s += "set logscale y\n";
  s += "set grid\nset key outside right\n";
  const std::string file = "figures/positions_" + folder_name(x.name) + "_" + folder_name(y.name) + ".png";
  const std::string error = run_gnuplot(s + "plot " + p + "\n", (fs::path(config.output) / file).string());
  return error.empty() ? "![" + x.name + " against " + y.name + "](" + file + ")\n\n"
                       : "*Figure not drawn: " + error + "*\n\n";
}

void write_parameter_space_figures(std::ostream& md, const StudyConfig& config, const StudyResult& result) {
  const auto& free = config.campaign.space.free_parameters();
  md << "\n## Calibrated sets in parameter space\n\nThe best set of every seed, one symbol per method (the paper's "
        "Figures 14, 17, 20, 23).\n\n";
  for (size_t a = 0; a < free.size(); ++a)
    for (size_t b = a + 1; b < free.size(); ++b) md << positions_figure(config, result, free[a], free[b]);
}

void write_markdown(const StudyConfig& config, const StudyResult& result) {
  std::ostringstream md;
  write_study_summary(md, config);
  write_five_best(md, config, result);
  write_fitness_tables(md, result);
  write_simulations_used(md, result);
  write_failed_campaigns(md, result);

  // Figures: mean best-so-far against simulations; the per-seed best sets in parameter space.
  fs::create_directories(fs::path(config.output) / "figures");
  write_convergence_figure(md, config, result);
  write_parameter_space_figures(md, config, result);
  std::ofstream out(result.markdown_path);
  out << md.str();
  if (!out) throw CampaignError(result.markdown_path + ": cannot write");
}

}  // namespace

StudyResult run_study(const StudyConfig& config, bool progress) {
  config.Validate();
  std::error_code ec;
  fs::create_directories(config.output, ec);
  if (ec) throw CampaignError(config.output + ": cannot create the study folder: " + ec.message());
  const size_t cases = config.campaign.cases.size();
  StudyResult result;
  for (const auto& method : config.methods) {
    StudyMethodResult r;
    r.method = method;
    r.method.iterations = method.iterations > 0 ? method.iterations : config.campaign.optimiser.iterations;
    r.method.label = method_label(method, r.method.iterations);
    for (const auto seed : config.seeds) {
      CampaignConfig c = config.campaign;
      c.name = config.campaign.name + "/" + r.method.label + "/seed-" + std::to_string(seed);
      c.optimiser.algorithm = method.algorithm;
      c.optimiser.iterations = r.method.iterations;
      c.optimiser.seed = seed;
      c.output = (fs::path(config.output) / folder_name(r.method.label) / ("seed-" + std::to_string(seed))).string();
      c.archive = (fs::path(config.output) / "archive.sqlite").string();
      c.report = false;
      RunOptions options;
      options.progress = false;
      options.resume = config.resume;
      options.note_fresh_resume = false;  // a study starts most of its campaigns fresh
      const CampaignResult campaign = run_campaign(c, options);
      StudyCampaign sc;
      sc.seed = seed;
      sc.status = campaign.status;
      sc.message = campaign.message;
      sc.best = campaign.best;
      sc.simulations = campaign.simulations;
      sc.simulated = campaign.simulated_this_session;
      sc.wall_time_s = campaign.wall_time_s;
      sc.best_history = campaign.best_history;
      r.simulations_per_campaign = std::max(r.simulations_per_campaign, sc.simulations);
      r.simulations_total += sc.simulations;
      r.wall_time_s += sc.wall_time_s;
      if (progress)
        std::cerr << r.method.label << " seed " << seed << ": best " << format_number(sc.best.fitness, six_digits) << " ("
                  << sc.simulations << " simulations, " << sc.simulated << " new, " << format_number(sc.wall_time_s, one_decimal)
                  << " s)" << (sc.status == CampaignStatus::completed ? "" : " FAILED: " + sc.message) << "\n";
      r.campaigns.push_back(std::move(sc));
    }
    std::vector<size_t> order;
    std::vector<double> values;
    for (size_t i = 0; i < r.campaigns.size(); ++i) {
      values.push_back(r.campaigns[i].best.fitness);
      if (std::isfinite(r.campaigns[i].best.fitness)) order.push_back(i);
    }
    std::stable_sort(order.begin(), order.end(),
                     [&](size_t a, size_t b) { return r.campaigns[a].best.fitness < r.campaigns[b].best.fitness; });
    order.resize(std::min<size_t>(order.size(), 5));
    r.five_best = order;
    r.fitness = fitness_statistics(values);
    result.methods.push_back(std::move(r));
  }
  result.common_budget = result.methods.front().simulations_per_campaign;
  for (const auto& r : result.methods) result.common_budget = std::min(result.common_budget, r.simulations_per_campaign);
  for (auto& r : result.methods) {
    std::vector<double> at_budget;
    for (const auto& c : r.campaigns) at_budget.push_back(best_after(c, result.common_budget, cases));
    r.fitness_at_common_budget = fitness_statistics(at_budget);
  }

  json methods = json::array();
  for (const auto& r : result.methods) {
    auto campaign_json = [&](const StudyCampaign& c) {
      return json{{"seed", c.seed},
                  {"status", c.status == CampaignStatus::completed ? "completed" : "failed"},
                  {"message", c.message},
                  {"params", c.best.params},
                  {"fitness", finite_or_null(c.best.fitness)},
                  {"fitness_at_common_budget", finite_or_null(best_after(c, result.common_budget, cases))},
                  {"simulations", c.simulations},
                  {"simulated_this_session", c.simulated},
                  {"wall_time_s", c.wall_time_s}};
    };
    json campaigns = json::array(), five = json::array();
    for (const auto& c : r.campaigns) campaigns.push_back(campaign_json(c));
    for (const size_t i : r.five_best) five.push_back(campaign_json(r.campaigns[i]));
    methods.push_back({{"label", r.method.label},
                       {"algorithm", r.method.algorithm},
                       {"iterations", r.method.iterations},
                       {"campaigns", campaigns},
                       {"five_best", five},
                       {"fitness", statistics_json(r.fitness)},
                       {"fitness_at_common_budget", statistics_json(r.fitness_at_common_budget)},
                       {"simulations_per_campaign", r.simulations_per_campaign},
                       {"simulations_total", r.simulations_total},
                       {"wall_time_s", r.wall_time_s}});
  }
  std::vector<std::uint64_t> seeds = config.seeds;
  const json study = {{"name", config.campaign.name},
                      {"objective", config.campaign.objective},
                      {"population", config.campaign.optimiser.population},
                      {"seeds", seeds},
                      {"common_budget", result.common_budget},
                      {"archive", (fs::path(config.output) / "archive.sqlite").string()},
                      {"methods", methods}};
  result.json_path = (fs::path(config.output) / "study.json").string();
  result.markdown_path = (fs::path(config.output) / "study.md").string();
  {
    std::ofstream out(result.json_path);
    out << study.dump(2) << "\n";
    if (!out) throw CampaignError(result.json_path + ": cannot write");
  }
  write_markdown(config, result);
  return result;
}

}  // namespace demcal::pipelines
