// report.md of a diagnosis: the verdict, the residual before and after (numbers and figures), and
// the table of candidate effects.
#include "demcal/pipelines/diagnose.hpp"
#include "diagnose_internal.hpp"

#include "demcal/dem/effects.hpp"
#include "demcal/pipelines/report.hpp"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>

namespace demcal::pipelines {

namespace fs = std::filesystem;

namespace {

std::string num(double v, int digits = 3) { return std::isfinite(v) ? format_number(v, digits) : "–"; }

std::string listed(const std::vector<double>& values) {
  std::string text;
  for (double v : values) text += (text.empty() ? "" : ", ") + num(v);
  return text;
}

// Measured, base and extended curves of one channel, and the two residuals, as two stacked plots.
std::string residual_figure(const ChannelResidual& base, const ChannelResidual* after, const std::string& after_label,
                            const fs::path& figures, const std::string& stem) {
  const fs::path data = figures / (stem + ".dat");
  {
    std::ofstream out(data);
    out << "# displacement_mm measured_kN base_kN after_kN\n";
    for (std::size_t i = 0; i < base.displacement.size(); ++i)
      out << base.displacement[i] * 1e3 << " " << base.measured[i] / 1e3 << " " << base.simulated[i] / 1e3 << " "
          << (after ? after->simulated[i] / 1e3 : base.simulated[i] / 1e3) << "\n";
  }
  std::ostringstream gp;
  gp << "set multiplot layout 2,1 title '" << base.case_name << ": force against " << base.channel << "'\n"
     << "set grid\nset xlabel 'displacement (mm)'\nset ylabel 'force (kN)'\nset key bottom center\n"
     << "plot '" << data.string() << "' u 1:2 w p pt 7 ps 0.4 lc rgb '#888888' t 'measured', "
     << "'' u 1:3 w l lw 2 lc rgb '#1f77b4' t 'base model'";
  if (after) gp << ", '' u 1:4 w l lw 2 lc rgb '#d62728' t '" << after_label << "'";
  gp << "\nset ylabel 'residual (kN)'\nset key below\n"
     << "plot '" << data.string() << "' u 1:($2-$3) w l lw 1.5 lc rgb '#1f77b4' t 'measured - base'";
  if (after) gp << ", '' u 1:($2-$4) w l lw 1.5 lc rgb '#d62728' t 'measured - " << after_label << "'";
  gp << ", " << base.noise / 1e3 << " w l dt 2 lc rgb '#444444' t '+/- noise', " << -base.noise / 1e3
     << " w l dt 2 lc rgb '#444444' notitle\nunset multiplot\n";
  const std::string png = stem + ".png";
  const std::string error = run_gnuplot(gp.str(), (figures / png).string());
  return error.empty() ? "![" + stem + "](figures/" + png + ")\n" : "(figure not drawn: " + error + ")\n";
}

}  // namespace

std::string detail::file_safe(std::string s) {
  for (auto& ch : s)
    if (!std::isalnum(static_cast<unsigned char>(ch)) && ch != '-' && ch != '_') ch = '_';
  return s;
}

namespace {

// The fit the residual figures compare with the base: the chosen effect's, else the best-scoring
// calibrated candidate's (null: none).
const EffectCandidate* fit_to_show(const Diagnosis& d) {
  const EffectCandidate* after = detail::chosen_candidate(d);
  if (!after)  // no choice: show the best-scoring calibrated candidate, for comparison
    for (const auto& c : d.candidates)
      if (c.tried && std::isfinite(c.score) && c.residuals.size() == d.base_residuals.size() &&
          (!after || c.score < after->score))
        after = &c;
  return after;
}

void write_verdict_and_base(std::ostream& md, const Diagnosis& d) {
  md << "# Diagnosis\n\n**" << d.headline << "**\n\n- " << d.conclusion << "\n";
  for (const auto& note : d.notes) md << "- " << note << "\n";
  md << "\nRMS force error over all channels: " << num(d.error_before) << " N before, " << num(d.error_after)
     << " N after. Simulations: " << d.simulations;
  if (d.simulated_this_session != d.simulations)
    md << " (" << d.simulated_this_session << " run by this session, the rest read from the archive)";
  md << "; wall time " << num(d.wall_time_s) << " s (simulations " << num(d.simulation_time_s) << " s, model "
     << num(d.model_time_s) << " s).\n\n"
     << "## Base fit\n\n| parameter | value |\n|---|---|\n";
  for (const auto& [k, v] : d.base_params) md << "| " << k << " | " << num(v, 4) << " |\n";
  if (!d.base_rerun_errors.empty())
    md << "\nRMS force error of the best set and of its re-runs with the parameters moved by 1e-7: "
       << listed(d.base_rerun_errors) << " N; the residual below is that of the run of median error.\n";
}

void write_base_residual(std::ostream& md, const Diagnosis& d, const EffectCandidate* after, const fs::path& figures) {
  md << "\n## Residual of the base fit (measured − simulated)\n\n"
     << "Noise is estimated from each measured curve alone (local three-point pseudo-residuals, median "
        "absolute deviation). A positive mean means the model is too weak there. Effective points: "
        "n (1 − ρ) / (1 + ρ) with ρ the lag-1 autocorrelation of the residual. Scatter: how much the "
        "simulated curve itself changes when the parameters move by 1e-7 of themselves (stick–slip events "
        "at other moments); no model can fit below it.\n\n"
     << "| case / channel | RMS (N) | noise (N) | scatter (N) | RMS / noise | bias (N) | trend (N/mm) | initial mean (N) | "
        "to peak mean (N) | after peak mean (N) | ρ | effective points |\n|---|---|---|---|---|---|---|---|---|---|---|---|\n";
  for (const auto& r : d.base_residuals) {
    const auto scatter = d.scatter.find(r.case_name + "/" + r.channel);
    md << "| " << r.case_name << " / " << r.channel << " | " << num(r.rms) << " | " << num(r.noise) << " | "
       << (scatter == d.scatter.end() ? std::string("–") : num(scatter->second)) << " | " << num(r.rms / r.noise) << " | " << num(r.bias) << " | " << num(r.trend / 1e3) << " | ";
    for (const auto& g : r.regions) md << (g.points > 0 ? num(g.mean) : std::string("–")) << " | ";
    md << num(r.autocorrelation) << " | " << num(r.effective_points) << " |\n";
  }
  md << "\n";
  for (std::size_t i = 0; i < d.base_residuals.size(); ++i) {
    const auto& r = d.base_residuals[i];
    const ChannelResidual* a = after && i < after->residuals.size() ? &after->residuals[i] : nullptr;
    md << residual_figure(r, a, a ? "base + " + after->effect : "", figures,
                          "residual-" + detail::file_safe(r.case_name + "-" + r.channel))
       << "\n";
  }
}

void write_candidates(std::ostream& md, const Diagnosis& d, const DiagnoseOptions& options) {
  md << "## Candidate effects\n\n"
     << "Signature: the share of the residual that the base parameters cannot remove and the effect's own "
        "change of the curves can. Criterion: change of the information criterion against the base fit "
        "(negative = better; accepted below −" << num(options.evidence) << "). RMS error: of the "
        "run of median error among the best set and its re-runs with the parameters moved by 1e-7 (all "
        "listed).\n\n"
     << "| effect | target | signature | simulations | RMS error (N) | best and re-runs (N) | on data not fitted (N) "
        "| criterion | verdict | why |\n"
        "|---|---|---|---|---|---|---|---|---|---|\n";
  for (const auto& c : d.candidates) {
    const std::string reruns = listed(c.rerun_errors);
    md << "| " << c.effect << " | " << (c.target.empty() ? "–" : c.target) << " | " << num(c.signature_score, 2)
       << " | " << c.simulations << " | " << num(c.error) << " | " << (reruns.empty() ? "–" : reruns) << " | "
       << num(c.held_out_error) << " | " << num(c.score) << " | " << to_string(c.verdict) << " | " << c.reason << " |\n";
  }
  md << "\n";
  std::ostringstream others;
  for (const auto& c : d.candidates)
    for (const auto& o : c.other_targets)
      others << "- " << c.effect << " was also calibrated at " << o.target << ", whose signature came close ("
             << num(o.signature_score, 2) << "): RMS error " << num(o.error) << " N in " << o.simulations
             << " simulations; the table keeps the better fit.\n";
  if (!others.str().empty()) md << others.str() << "\n";
  if (!d.effective_points.empty()) {
    std::string counts;
    for (const auto& [key, n] : d.effective_points)
      counts += (counts.empty() ? " " : "; ") + key + " " + num(n) + " (" + d.effective_points_from.at(key) + ")";
    md << "The criterion counts every fit with the same effective points per channel, those of the fit closest "
          "to the measurement there:" << counts << ".\n\n";
  }
}

void write_held_out(std::ostream& md, const Diagnosis& d, const DiagnoseOptions& options) {
  if (!d.held_out_rms.empty()) {
    md << "Data not fitted (channels of weight 0, held-out cases) and the base fit's RMS error there. A channel "
          "checks the fits only where the base fit reproduces it (RMS at most "
       << num(options.held_out_ratio, 2)
       << " x its noise); one the base fit misses is reported, not judged:\n\n"
          "| case / channel | RMS (N) | noise (N) | checks the fits |\n|---|---|---|---|\n";
    for (const auto& [key, rms] : d.held_out_rms) {
      const bool checks = std::find(d.held_out_checked.begin(), d.held_out_checked.end(), key) != d.held_out_checked.end();
      md << "| " << key << " | " << num(rms) << " | " << num(d.held_out_noise.at(key)) << " | " << (checks ? "yes" : "no")
         << " |\n";
    }
    md << "\n";
  } else {
    md << "No data was left out of the fits (no channel of weight 0, no `--held-out` case): the fits are not "
          "checked on data they did not use.\n\n";
  }
}

void write_best_sets(std::ostream& md, const Diagnosis& d, const DiagnoseOptions& options) {
  for (const auto& c : d.candidates) {
    if (!c.tried || c.params.empty()) continue;
    md << "### " << c.effect << ": best set\n\n| parameter | value |\n|---|---|\n";
    for (const auto& [k, v] : c.params) md << "| " << k << " | " << num(v, 4) << " |\n";
    md << "\n";
    if (!c.search_ranges.empty()) {
      md << "Searched:";
      const dem::Effect& effect = dem::find_effect(c.effect);
      for (const auto& [k, range] : c.search_ranges) {
        md << " " << k << " " << num(range[0]) << " to " << num(range[1]);
        for (const auto& p : effect.parameters)
          if (p.name == dem::parameter_field(k))
            if (const std::string words = dem::scaled_range_words(p, {d.peak_normal_stress, d.start_normal_stress}); !words.empty())
              md << " (" << words << ")";
        md << ";";
      }
      md.seekp(-1, std::ios_base::cur);
      md << ".\n\n";
    }
    if (c.union_search.rounds > 0) md << c.union_search.describe(c.effect) << "\n\n";
    if (c.continued.simulations > 0) md << c.continued.describe(c.effect) << "\n\n";
    if (c.bounds.empty()) continue;
    md << "How tightly the data pin the effect's parameters: each moved from the best set, the other free "
          "parameters re-fitted where the move alone fits worse (marked *); a value is ruled out when the criterion "
          "still rises by more than " << num(options.evidence)
       << " (the margin an effect needs to be accepted).\n\n| parameter | values tried (criterion change) | bound |\n|---|---|---|\n";
    for (const auto& b : c.bounds) {
      md << "| " << b.name << " | ";
      for (std::size_t i = 0; i < b.trials.size(); ++i) {
        const double v = b.trials[i].first;
        const bool refit = std::find(b.refitted.begin(), b.refitted.end(), v) != b.refitted.end();
        md << (i ? ", " : "") << num(v) << " (" << num(b.trials[i].second, 2) << (refit ? "*" : "") << ")";
      }
      md << " | " << b.describe() << " |\n";
    }
    md << "\n";
  }
}

}  // namespace

void detail::write_diagnosis_report(const Diagnosis& d, const DiagnoseOptions& options) {
  const fs::path out_dir = options.out, figures = out_dir / "figures";
  fs::create_directories(figures);
  std::ostringstream md;
  write_verdict_and_base(md, d);
  write_base_residual(md, d, fit_to_show(d), figures);
  write_candidates(md, d, options);
  write_held_out(md, d, options);
  write_best_sets(md, d, options);
  const fs::path path = out_dir / "report.md";
  std::ofstream out(path);
  out << md.str();
  if (!out) throw CampaignError("cannot write " + path.string());
}

}  // namespace demcal::pipelines
