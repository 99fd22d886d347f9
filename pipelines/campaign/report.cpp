#include "demcal/pipelines/report.hpp"

#include "demcal/common/format.hpp"
#include "demcal/pipelines/process.hpp"
#include "demcal/pipelines/version.hpp"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <sstream>

namespace demcal::pipelines {

namespace fs = std::filesystem;
using nlohmann::json;

std::string png_terminal() {
  static std::once_flag once;
  static std::string terminal = "png";
  std::call_once(once, [] {
    const fs::path probe = fs::temp_directory_path() / ("demcal-gnuplot-probe-" + std::to_string(::getpid()));
    ProcessOptions o;
    o.argv = {"gnuplot", "-e", "set terminal"};
    o.stdout_path = probe.string();
    o.stderr_path = probe.string();
    o.timeout_s = 20;
    if (run_process(o).ok()) {
      std::ifstream in(probe);
      std::stringstream text;
      text << in.rdbuf();
      if (text.str().find("pngcairo") != std::string::npos) terminal = "pngcairo";
    }
    std::error_code ec;
    fs::remove(probe, ec);
  });
  return terminal;
}

std::string run_gnuplot(const std::string& script, const std::string& png_path) {
  const std::string script_path = png_path + ".gp";
  {
    std::ofstream out(script_path);
    out << "set terminal " << png_terminal() << " size 900,600 noenhanced\n"
        << "set output '" << png_path << "'\n"
        << script << "\nset output\n";
    if (!out) return "cannot write " + script_path;
  }
  ProcessOptions o;
  o.argv = {"gnuplot", script_path};
  o.stderr_path = png_path + ".log";
  o.timeout_s = 60;
  const ProcessResult r = run_process(o);
  if (!r.ok()) {
    std::ifstream in(o.stderr_path);
    std::stringstream text;
    text << in.rdbuf();
    std::string why = "gnuplot " + r.message;
    if (!text.str().empty()) why += ": " + text.str().substr(0, 400);
    return why;
  }
  std::error_code ec;
  fs::remove(o.stderr_path, ec);
  return fs::exists(png_path) ? "" : "gnuplot wrote no " + png_path;
}

namespace {

// Numbers in tables and gnuplot scripts; NaN and +/-inf are "-".
constexpr NumberFormat six_digits{.significant_digits = 6, .non_finite = "-"};
constexpr NumberFormat ten_digits{.significant_digits = 10, .non_finite = "-"};
constexpr NumberFormat one_decimal{.fixed_decimals = 1, .non_finite = "-"};
constexpr NumberFormat two_decimals{.fixed_decimals = 2, .non_finite = "-"};
constexpr NumberFormat three_decimals{.fixed_decimals = 3, .non_finite = "-"};
constexpr NumberFormat six_decimals{.fixed_decimals = 6, .non_finite = "-"};

std::string datablock(const std::string& name, const std::vector<std::vector<double>>& rows) {
  std::string text = "$" + name + " << EOD\n";
  for (const auto& row : rows) {
    for (size_t i = 0; i < row.size(); ++i) text += (i ? " " : "") + format_number(row[i], ten_digits);
    text += "\n";
  }
  return text + "EOD\n";
}

// Value shown in tables: stiffnesses in GPa/m, friction in degrees, others as they are.
std::string table_value(const std::string& name, double value) {
  const bool stiffness = name == "kn" || name == "ks" || name.ends_with(".kn") || name.ends_with(".ks");
  return stiffness ? format_number(value / 1e9, three_decimals) : format_number(value, two_decimals);
}
std::string table_header(const std::string& name) {
  const bool stiffness = name == "kn" || name == "ks" || name.ends_with(".kn") || name.ends_with(".ks");
  if (stiffness) return name + " (GPa/m)";
  if (name.ends_with("friction_deg")) return name + " (°)";
  return name;
}

struct Figure {
  std::string file;     // relative to out_dir
  std::string caption;
  std::string error;    // "" when drawn
};

std::string figure_markdown(const Figure& f) {
  if (!f.error.empty()) return "*Figure not drawn (" + f.caption + "): " + f.error + "*\n\n";
  return "![" + f.caption + "](" + f.file + ")\n\n*" + f.caption + "*\n\n";
}

Figure fit_figure(const ReportInputs& in, size_t k, const std::string& channel, const std::string& dir,
                  const std::string& out_dir) {
  const auto& measured = in.measured[k];
  const auto& run = in.best_runs[k];
  Figure f;
  f.file = "figures/fit_" + in.config->cases[k].name + "_" + channel + ".png";
  f.caption = "Case " + in.config->cases[k].name + ", channel " + channel + ": best fit over the measured curve";
  std::vector<std::vector<double>> m, s, ms, ss;
  const auto mseries = smoothing::series(measured, channel, "force");
  for (size_t i = 0; i < mseries.x.size(); ++i) m.push_back({mseries.x[i] * 1e3, mseries.y[i] / 1e3});
  if (run.curves.has_column(channel) && run.curves.has_column("force")) {
    const auto sseries = smoothing::series(run.curves, channel, "force");
    const size_t stride = std::max<size_t>(1, sseries.x.size() / 2000);
    for (size_t i = 0; i < sseries.x.size(); i += stride) s.push_back({sseries.x[i] * 1e3, sseries.y[i] / 1e3});
  }
  std::string script = datablock("measured", m) + datablock("simulated", s);
  std::string plot = "plot $measured using 1:2 with points pt 7 ps 0.5 lc rgb '#555555' title 'measured', "
                     "$simulated using 1:2 with lines lw 1.5 lc rgb '#1f77b4' title 'best simulation'";
  if (k < in.smoothed_measured.size() && in.smoothed_measured[k].count(channel)) {
    const auto& sm = in.smoothed_measured[k].at(channel);
    for (size_t i = 0; i < sm.x.size(); ++i) ms.push_back({sm.x[i] * 1e3, sm.y[i] / 1e3});
    script += datablock("measured_smooth", ms);
    plot += ", $measured_smooth using 1:2 with lines lw 2 dt 2 lc rgb '#000000' title 'measured, smoothed'";
  }
  if (k < in.smoothed_best.size() && in.smoothed_best[k].count(channel)) {
    const auto& sb = in.smoothed_best[k].at(channel);
    for (size_t i = 0; i < sb.x.size(); ++i) ss.push_back({sb.x[i] * 1e3, sb.y[i] / 1e3});
    script += datablock("simulated_smooth", ss);
    plot += ", $simulated_smooth using 1:2 with lines lw 2 dt 2 lc rgb '#d62728' title 'simulation, smoothed'";
  }
  script += "set xlabel '" + channel + " (mm)'\nset ylabel 'force (kN)'\nset grid\nset key bottom right\n"
            "set autoscale xfix\nset offsets graph 0.02, graph 0.02, 0, 0\n" + plot + "\n";
  f.error = run_gnuplot(script, (fs::path(out_dir) / f.file).string());
  return f;
}

Figure convergence_figure(const ReportInputs& in, const std::string& out_dir) {
  Figure f;
  f.file = "figures/convergence.png";
  f.caption = "Convergence: best fitness against simulations";
  std::vector<std::vector<double>> rows, all;
  const long cases = static_cast<long>(in.config->cases.size());
  for (size_t i = 0; i < in.result->best_history.size(); ++i) {
    if (std::isfinite(in.result->best_history[i])) rows.push_back({double((i + 1) * cases), in.result->best_history[i]});
    if (std::isfinite(in.result->all[i].fitness)) all.push_back({double((i + 1) * cases), in.result->all[i].fitness});
  }
  const std::string script = datablock("best", rows) + datablock("all", all) +
                             "set xlabel 'simulations'\nset ylabel 'fitness'\nset logscale y\nset grid\n"
                             "plot $all using 1:2 with points pt 7 ps 0.4 lc rgb '#aaaaaa' title 'each candidate', "
                             "$best using 1:2 with steps lw 2 lc rgb '#1f77b4' title 'best so far'\n";
  f.error = run_gnuplot(script, (fs::path(out_dir) / f.file).string());
  return f;
}

// Tick marks of a logarithmic colour bar over the fitness values (third column): 1, 2, 5 x 10^n
// inside the range, so that a range of less than a decade still gets labelled ticks.
std::string colour_bar_tics(const std::vector<std::vector<double>>& rows) {
  double lo = INFINITY, hi = 0;
  for (const auto& r : rows)
    if (r.size() > 2 && r[2] > 0) lo = std::min(lo, r[2]), hi = std::max(hi, r[2]);
  if (!(hi > lo)) return "";
  std::string tics;
  for (double decade = std::pow(10.0, std::floor(std::log10(lo))); decade <= hi; decade *= 10)
    for (double m : {1.0, 2.0, 5.0})
      if (m * decade >= lo && m * decade <= hi) tics += (tics.empty() ? "" : ", ") + format_number(m * decade, six_digits);
  return tics.empty() ? "" : "set cbtics (" + tics + ")\n";
}

std::vector<Figure> parameter_space_figures(const ReportInputs& in, const std::string& out_dir) {
  std::vector<Figure> figures;
  const auto& free = in.config->space.free_parameters();
  for (size_t a = 0; a < free.size(); ++a)
    for (size_t b = a + 1; b < free.size(); ++b) {
      Figure f;
      f.file = "figures/parameters_" + free[a].name + "_" + free[b].name + ".png";
      f.caption = "Evaluated parameter sets (grey, coloured by fitness) and the five best (numbered): " +
                  free[a].name + " against " + free[b].name;
      auto scaled = [](const std::string& name, double v) {
        return (name == "kn" || name == "ks" || name.ends_with(".kn") || name.ends_with(".ks")) ? v / 1e9 : v;
      };
      std::vector<std::vector<double>> all, top;
      for (const auto& s : in.result->all)
        if (std::isfinite(s.fitness))
          all.push_back({scaled(free[a].name, s.params.at(free[a].name)), scaled(free[b].name, s.params.at(free[b].name)),
                         s.fitness});
      for (size_t i = 0; i < in.result->top.size(); ++i) {
        const auto& s = in.result->top[i];
        top.push_back({scaled(free[a].name, s.params.at(free[a].name)), scaled(free[b].name, s.params.at(free[b].name)),
                       double(i + 1)});
      }
      std::string script = datablock("all", all) + datablock("top", top);
      script += "set xlabel '" + table_header(free[a].name) + "'\nset ylabel '" + table_header(free[b].name) + "'\n";
      script += "set xrange [" + format_number(scaled(free[a].name, free[a].lower), six_digits) + ":" +
                format_number(scaled(free[a].name, free[a].upper), six_digits) + "]\n";
      script += "set yrange [" + format_number(scaled(free[b].name, free[b].lower), six_digits) + ":" +
                format_number(scaled(free[b].name, free[b].upper), six_digits) + "]\n";
      if (free[a].scale == optimise::ParameterSpec::Scale::log10) script += "set logscale x\n";
      if (free[b].scale == optimise::ParameterSpec::Scale::log10) script += "set logscale y\n";
      script += colour_bar_tics(all);
      script += "set logscale cb\nset cblabel 'fitness'\nset palette rgb 33,13,10\nset grid\n"
                "plot $all using 1:2:3 with points pt 7 ps 0.6 lc palette title 'evaluated', "
                "$top using 1:2 with points pt 6 ps 2.5 lw 2 lc rgb '#d62728' title 'five best', "
                "$top using 1:2:(sprintf('%d', $3)) with labels offset 1.2,1.2 tc rgb '#d62728' notitle\n";
      f.error = run_gnuplot(script, (fs::path(out_dir) / f.file).string());
      figures.push_back(f);
    }
  return figures;
}

Figure failure_figure(const ReportInputs& in, size_t k, const std::string& out_dir) {
  Figure f;
  f.file = "figures/failure_" + in.config->cases[k].name + ".png";
  f.caption = "Failure mode of the best run (case " + in.config->cases[k].name +
              "): blocks at the end of the run coloured by displacement (mm); hinges o, sliding joints ^";
  const json& d = in.best_runs[k].details;
  if (!d.contains("final_blocks") || d["final_blocks"].empty()) {
    f.error = "the backend recorded no final block state";
    return f;
  }
  std::map<std::string, std::vector<std::pair<double, double>>> vertices;
  std::string objects;
  double max_disp = 0;
  int object_id = 1;
  for (const auto& b : d["final_blocks"]) {
    const double dx = b["displacement"][0].get<double>(), dy = b["displacement"][1].get<double>();
    const double magnitude = std::hypot(dx, dy) * 1e3;
    max_disp = std::max(max_disp, magnitude);
    auto& vs = vertices[b["name"].get<std::string>()];
    std::string poly = "set object " + std::to_string(object_id++) + " polygon from ";
    for (size_t i = 0; i <= b["vertices"].size(); ++i) {
      const auto& v = b["vertices"][i % b["vertices"].size()];
      if (i < b["vertices"].size()) vs.push_back({v[0].get<double>(), v[1].get<double>()});
      poly += (i ? " to " : "") + format_number(v[0].get<double>(), six_decimals) + "," +
              format_number(v[1].get<double>(), six_decimals);
    }
    poly += b["fixed"].get<bool>() ? " fc rgb '#bbbbbb' fs solid 0.6 border lc rgb '#333333'\n"
                                   : " fc palette cb " + format_number(magnitude, six_decimals) + " fs solid 1.0 border lc rgb '#333333'\n";
    objects += poly;
  }
  // A joint's marker: the mean of the closest vertex pairs of its two blocks.
  auto joint_point = [&](const std::string& joint, double& x, double& y) {
    const size_t slash = joint.find('/');
    if (slash == std::string::npos) return false;
    const auto a = vertices.find(joint.substr(0, slash)), b = vertices.find(joint.substr(slash + 1));
    if (a == vertices.end() || b == vertices.end()) return false;
    std::vector<std::pair<double, std::pair<double, double>>> pairs;
    for (const auto& p : a->second) {
      double best = INFINITY;
      std::pair<double, double> mid;
      for (const auto& q : b->second) {
        const double dist = std::hypot(p.first - q.first, p.second - q.second);
        if (dist < best) best = dist, mid = {(p.first + q.first) / 2, (p.second + q.second) / 2};
      }
      pairs.push_back({best, mid});
    }
    std::sort(pairs.begin(), pairs.end(), [](const auto& l, const auto& r) { return l.first < r.first; });
    const size_t n = std::min<size_t>(2, pairs.size());
    x = y = 0;
    for (size_t i = 0; i < n; ++i) x += pairs[i].second.first / n, y += pairs[i].second.second / n;
    return n > 0;
  };
  std::vector<std::vector<double>> hinges, sliding, extent;
  for (const auto& name : d.value("hinges", json::array())) {
    double x, y;
    if (joint_point(name.get<std::string>(), x, y)) hinges.push_back({x, y});
  }
  for (const auto& name : d.value("sliding_joints", json::array())) {
    double x, y;
    if (joint_point(name.get<std::string>(), x, y)) sliding.push_back({x, y});
  }
  double xmin = INFINITY, xmax = -INFINITY, ymin = INFINITY, ymax = -INFINITY;
  for (const auto& [name, vs] : vertices)
    for (const auto& [x, y] : vs) xmin = std::min(xmin, x), xmax = std::max(xmax, x), ymin = std::min(ymin, y), ymax = std::max(ymax, y);
  const double pad = 0.05 * std::max(xmax - xmin, ymax - ymin);
  extent.push_back({xmin, ymin});
  if (hinges.empty()) hinges.push_back({NAN, NAN});
  if (sliding.empty()) sliding.push_back({NAN, NAN});
  std::string script = datablock("hinges", hinges) + datablock("sliding", sliding) + datablock("extent", extent);
  script += "set size ratio -1\nset xrange [" + format_number(xmin - pad, six_digits) + ":" + format_number(xmax + pad, six_digits) +
            "]\nset yrange [" + format_number(ymin - pad, six_digits) + ":" + format_number(ymax + pad, six_digits) + "]\n";
  script += "set cbrange [0:" + format_number(std::max(max_disp, 1e-6), six_digits) + "]\nset cblabel 'displacement (mm)'\n"
            "set palette rgb 33,13,10\nset xlabel 'x (m)'\nset ylabel 'y (m)'\nset key top left\n";
  script += objects;
  script += "plot $extent using 1:2:(0) with points pt 0 lc palette notitle, "
            "$hinges using 1:2 with points pt 6 ps 2.5 lw 2.5 lc rgb '#d62728' title 'hinge', "
            "$sliding using 1:2 with points pt 8 ps 2.5 lw 2.5 lc rgb '#000000' title 'sliding joint'\n";
  f.error = run_gnuplot(script, (fs::path(out_dir) / f.file).string());
  return f;
}

void write_summary(std::ostream& md, const ReportInputs& in) {
  const auto& config = *in.config;
  const auto& result = *in.result;
  md << "# Calibration report: " << config.name << "\n\n";
  md << "demcal " << version() << "; algorithm " << config.optimiser.algorithm << ", population "
     << config.optimiser.population << ", seed " << config.optimiser.seed << ", objective " << config.objective
     << "; " << result.iterations << " iterations, " << result.simulations << " simulations (" << result.failed_runs
     << " candidates without a finite fitness: a failed run, or a curve with no displacement window in common with "
        "the measurement, which ranks worst); optimiser status " << result.optimiser_status << ".\n\n";
}

void write_best_parameters(std::ostream& md, const ReportInputs& in) {
  const auto& result = *in.result;
  md << "## Best parameters\n\n| parameter | value |\n| --- | --- |\n";
  for (const auto& [name, value] : result.best.params) md << "| " << name << " | " << format_number(value, six_digits) << " |\n";
  md << "| fitness | " << format_number(result.best.fitness, six_digits) << " |\n\n";
  md << "Units: kn, ks in Pa/m, friction_deg in degrees; fitness in N (sum over channels of the root of the "
        "summed squared force differences at " << in.config->objective_options.points << " points).\n\n";
}

void write_best_fits(std::ostream& md, const ReportInputs& in, const std::string& out_dir) {
  const auto& config = *in.config;
  md << "## Best fit against the measured curves\n\n";
  for (size_t k = 0; k < config.cases.size() && k < in.best_runs.size(); ++k) {
    md << "Case **" << config.cases[k].name << "** (" << config.cases[k].measured.file << "): best run status "
       << in.best_runs[k].status;
    if (!in.best_runs[k].message.empty()) md << " (" << in.best_runs[k].message << ")";
    md << ".\n\n";
    std::vector<std::string> channels;
    try {
      channels = smoothing::common_channels(in.measured[k], in.best_runs[k].curves, config.objective_options);
    } catch (const std::exception& e) {
      md << "*No channel to plot: " << e.what() << "*\n\n";
    }
    for (const auto& channel : channels) md << figure_markdown(fit_figure(in, k, channel, "figures", out_dir));
  }
}

// The layout of the paper's Tables 1-4.
void write_five_best(std::ostream& md, const ReportInputs& in) {
  const auto& config = *in.config;
  const auto& result = *in.result;
  md << "## Five best parameter sets\n\nLayout of the paper's Tables 1-4 (one row per distinct set, best first).\n\n";
  md << "| Calibration process | Number of iterations | Run ID |";
  const auto free = config.space.free_names();
  for (const auto& name : free) md << " " << table_header(name) << " |";
  md << " Fitness (-) |\n| --- | --- | --- |";
  for (size_t i = 0; i < free.size(); ++i) md << " --- |";
  md << " --- |\n";
  for (size_t i = 0; i < result.top.size(); ++i) {
    md << "| " << (i == 0 ? config.optimiser.algorithm : "") << " | " << (i == 0 ? std::to_string(result.iterations) : "")
       << " | " << i + 1 << " |";
    for (const auto& name : free) md << " " << table_value(name, result.top[i].params.at(name)) << " |";
    md << " " << format_number(result.top[i].fitness, one_decimal) << " |\n";
  }
}

// The identifiability block of result.json as a table, with how the ranges were obtained.
void write_identifiability(std::ostream& md, const ReportInputs& in) {
  const auto& id = in.result->identifiability;
  if (id.parameters.empty()) return;
  md << "\n## Identifiability\n\nValues that fit within the noise band: fitness <= best x (1 + "
     << format_number(id.relative_band, three_decimals) << ") = " << format_number(id.band_fitness, one_decimal) << " ("
     << id.sets_in_band << " evaluated sets in it). ";
  if (id.method == "profile") {
    const auto& p = id.profile;
    md << "Range: the parameter's profile on an emulator (Gaussian process on " << (p.log_transformed ? "log " : "")
       << "fitness, " << p.training_rows << " runs, leave-one-out relative error "
       << format_number(p.loo_relative_error, three_decimals) << "; the others re-optimised at each of "
       << id.options.grid_points << " values) within " << format_number(p.threshold, one_decimal)
       << " (the band over the larger of the best fitness and the emulator's minimum, "
       << format_number(p.emulator_minimum, one_decimal) << "), joined with the range of the evaluated sets.\n\n";
  } else {
    md << "Range: over the evaluated sets only (" << id.method_note << ").\n\n";
  }
  md << "| parameter | best | range | evaluated sets | profile |\n| --- | --- | --- | --- | --- |\n";
  auto range = [](const std::string& name, double lo, double hi) {
    if (!std::isfinite(lo)) return std::string("-");
    return table_value(name, lo) + " - " + table_value(name, hi);
  };
  for (const auto& name : id.coordinate_names.empty() ? in.config->space.free_names() : id.coordinate_names) {
    const auto it = id.parameters.find(name);
    if (it == id.parameters.end()) continue;
    const auto& r = it->second;
    md << "| " << table_header(name) << " | " << table_value(name, r.best) << " | " << range(name, r.min, r.max) << " | "
       << range(name, r.evaluated_min, r.evaluated_max) << " | " << range(name, r.profile_min, r.profile_max) << " |\n";
  }
  md << "\n";
}

void write_failure_modes(std::ostream& md, const ReportInputs& in, const std::string& out_dir) {
  const auto& config = *in.config;
  md << "## Failure mode\n\n";
  for (size_t k = 0; k < config.cases.size() && k < in.best_runs.size(); ++k) {
    const json& d = in.best_runs[k].details;
    if (d.contains("hinges"))
      md << "Case " << config.cases[k].name << ": hinges " << d["hinges"].dump() << "; sliding joints "
         << d.value("sliding_joints", json::array()).dump() << ".\n\n";
    md << figure_markdown(failure_figure(in, k, out_dir));
  }
}

void write_failed_runs(std::ostream& md, const std::vector<ReportInputs::Failure>& failures) {
  if (failures.empty()) return;
  constexpr size_t kListed = 100;
  md << "## Failed runs\n\n" << failures.size()
     << " run(s) left their candidate without a finite fitness; the optimiser ranked those candidates worst "
        "and went on.";
  if (failures.size() > kListed) md << " The first " << kListed << " are listed.";
  md << "\n\n| iteration | candidate | case | parameters | status | reason |\n| --- | --- | --- | --- | --- | --- |\n";
  for (size_t i = 0; i < failures.size() && i < kListed; ++i) {
    const auto& f = failures[i];
    std::string params, reason = f.reason;
    for (const auto& [name, value] : f.params) params += (params.empty() ? "" : ", ") + name + " " + format_number(value, six_digits);
    for (auto& c : reason)
      if (c == '|' || c == '\n') c = '/';
    md << "| " << f.iteration << " | " << f.position << " | " << f.case_name << " | " << params << " | " << f.status
       << " | " << reason << " |\n";
  }
  md << "\n";
}

void write_surrogate_model(std::ostream& md, const ReportInputs& in) {
  const auto& config = *in.config;
  const auto& result = *in.result;
  const bool mlp = result.surrogate_kind == "mlp";
  md << "Model: " << result.surrogate_kind
     << (mlp ? " (an ensemble of " + std::to_string(config.surrogate.options.mlp.members) +
                   " neural networks predicting the curves, scored by the campaign's objective)"
             : std::string(" (Gaussian process on the fitness, ARD Matern-5/2, fitted nugget)"))
     << "; acquisition " << surrogate::to_string(config.surrogate.options.acquisition) << ". "
     << (mlp ? "5-fold" : "Leave-one-out") << " relative error of the final model: "
     << (std::isfinite(result.surrogate_cv_error) ? format_number(result.surrogate_cv_error, three_decimals) : std::string("n/a"))
     << " (0 = exact, 1 = no better than the mean).\n\n";
}

// Per screened iteration: how many runs trained the model, how many were proposed and simulated.
void write_screened_iterations(std::ostream& md, const CampaignResult& result) {
  md << "| iteration | training runs | pool | simulated | model error on the simulated (mean relative) |\n"
        "| --- | --- | --- | --- | --- |\n";
  for (const auto& it : result.surrogate_iterations) {
    md << "| " << it.at("iteration").get<int>() + 1 << " | " << it.value("training_rows", 0L) << " | "
       << it.at("pool").get<long>() << " | " << it.at("simulated").get<long>() << " | "
       << (it.at("mean_relative_error").is_number() ? format_number(it.at("mean_relative_error").get<double>(), three_decimals)
                                                    : std::string("n/a"))
       << " |\n";
  }
}

void write_screened_out_candidates(std::ostream& md, const ReportInputs& in) {
  md << "\nScreened out (predicted fitness and probability of failure):\n\n"
        "| iteration | slot | parameters | predicted fitness | P(failure) |\n| --- | --- | --- | --- | --- |\n";
  const auto free = in.config->space.free_names();
  for (const auto& it : in.result->surrogate_iterations)
    for (const auto& c : it.at("candidates")) {
      if (c.at("simulated").get<bool>()) continue;
      md << "| " << it.at("iteration").get<int>() + 1 << " | " << c.at("slot").get<int>() << " | ";
      const auto x = c.at("x").get<std::vector<double>>();
      for (size_t k = 0; k < free.size() && k < x.size(); ++k)
        md << (k ? ", " : "") << free[k] << " " << table_value(free[k], x[k]);
      md << " | " << format_number(c.at("predicted_fitness").get<double>(), one_decimal) << " | "
         << format_number(c.at("failure_probability").get<double>(), two_decimals) << " |\n";
    }
  md << "\n";
}

void write_surrogate(std::ostream& md, const ReportInputs& in) {
  const auto& result = *in.result;
  if (!result.surrogate_used) return;
  md << "## Surrogate\n\n";
  write_surrogate_model(md, in);
  if (in.config->optimiser.algorithm == "bo") {
    md << "Bayesian optimisation: every candidate after the initial design was the acquisition's optimum; "
       << result.candidates << " simulations.\n\n";
    return;
  }
  const long proposed = result.surrogate_simulated + result.surrogate_screened_out;
  md << "Simulations saved: " << result.surrogate_screened_out << " of the " << proposed
     << " candidates the optimiser proposed in screened iterations were screened out (never simulated); "
     << result.surrogate_screened << " pool points were ranked.\n\n";
  write_screened_iterations(md, result);
  write_screened_out_candidates(md, in);
}

}  // namespace

std::string write_report(const ReportInputs& in, const std::string& out_dir) {
  fs::create_directories(fs::path(out_dir) / "figures");
  std::ostringstream md;
  write_summary(md, in);
  write_best_parameters(md, in);
  write_best_fits(md, in, out_dir);
  md << "## Convergence\n\n" << figure_markdown(convergence_figure(in, out_dir));
  write_five_best(md, in);
  write_identifiability(md, in);
  md << "\n## Calibrated sets in parameter space\n\n";
  for (const auto& f : parameter_space_figures(in, out_dir)) md << figure_markdown(f);
  write_failure_modes(md, in, out_dir);
  write_failed_runs(md, in.failures);
  write_surrogate(md, in);

  const std::string path = (fs::path(out_dir) / "report.md").string();
  std::ofstream out(path);
  out << md.str();
  if (!out) throw std::runtime_error(path + ": cannot write the report");
  return path;
}

}  // namespace demcal::pipelines
