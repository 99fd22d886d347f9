#include "demcal/pipelines/backend.hpp"

#include "demcal/common/format.hpp"
#include "demcal/dem/simulation.hpp"
#include "demcal/pipelines/archive.hpp"
#include "demcal/pipelines/process.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <csignal>
#include <cstdlib>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <deque>
#include <exception>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <sstream>
#include <stdexcept>
#include <thread>

namespace demcal::pipelines {

namespace fs = std::filesystem;

int hardware_threads() { return std::max(1u, std::thread::hardware_concurrency()); }

SimulationOutcome outcome_from_recording(const dem::Recording& rec) {
  SimulationOutcome out;
  out.status = dem::to_string(rec.status);
  out.message = rec.message;
  out.wall_time_s = rec.wall_time_s;
  out.curves.source = "simulation";
  out.curves.columns.push_back({"time", "s", rec.time});
  out.curves.columns.push_back({"force", "N", rec.force});
  for (size_t g = 0; g < rec.gauge_names.size() && g < rec.gauge_values.size(); ++g)
    out.curves.columns.push_back({rec.gauge_names[g], "m", rec.gauge_values[g]});
  auto& d = out.details;
  d["peak_force"] = rec.peak_force;
  d["steps"] = rec.steps;
  d["gravity_steps"] = rec.gravity_steps;
  d["time_step"] = rec.time_step;
  d["max_block_displacement"] = rec.max_block_displacement;
  d["max_normal_stress"] = rec.max_normal_stress;
  d["start_normal_stress"] = rec.start_normal_stress;
  d["hinges"] = rec.hinges;
  d["sliding_joints"] = rec.sliding_joints;
  nlohmann::json joints = nlohmann::json::array();
  for (const auto& j : rec.joints)
    joints.push_back({{"name", j.name}, {"joint_group", j.joint_group}, {"open_fraction", j.open_fraction},
                      {"rotation", j.rotation}, {"slip", j.slip}, {"hinge", j.hinge}, {"sliding", j.sliding},
                      {"max_normal_stress", j.max_normal_stress}});
  d["joints"] = joints;
  nlohmann::json blocks = nlohmann::json::array();
  for (const auto& b : rec.final_blocks) {
    nlohmann::json vertices = nlohmann::json::array();
    for (const auto& v : b.vertices) vertices.push_back({v.x(), v.y()});
    blocks.push_back({{"name", b.name}, {"vertices", vertices}, {"displacement", {b.displacement.x(), b.displacement.y()}},
                      {"rotation", b.rotation}, {"fixed", b.fixed}});
  }
  d["final_blocks"] = blocks;
  return out;
}

SimulationOutcome simulate_with_parameters(const dem::Scene& scene, const std::map<std::string, double>& params,
                                           const std::atomic<bool>* cancel) {
  const auto start = std::chrono::steady_clock::now();
  try {
    dem::Scene copy = scene;
    for (const auto& [name, value] : params) dem::set_parameter(copy, name, value);
    dem::RunControl control;
    control.cancel = cancel;
    return outcome_from_recording(dem::simulate(copy, control));
  } catch (const std::exception& e) {
    SimulationOutcome out;
    out.status = "failed";
    out.message = e.what();
    out.wall_time_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return out;
  }
}

void run_pool(std::size_t count, int threads, const std::function<SimulationOutcome(std::size_t)>& work,
              const OutcomeCallback& on_done) {
  if (count == 0) return;
  const int n = std::max(1, std::min<int>(threads, static_cast<int>(count)));
  if (n == 1) {
    for (std::size_t i = 0; i < count; ++i) on_done(i, work(i));
    return;
  }
  std::mutex mutex;
  std::condition_variable ready;
  std::deque<std::pair<std::size_t, SimulationOutcome>> finished;
  std::size_t next = 0;
  std::vector<std::thread> pool;
  for (int t = 0; t < n; ++t)
    pool.emplace_back([&] {
      while (true) {
        std::size_t index;
        {
          std::lock_guard<std::mutex> lock(mutex);
          if (next >= count) return;
          index = next++;
        }
        SimulationOutcome outcome;
        try {
          outcome = work(index);
        } catch (const std::exception& e) {
          outcome.status = "failed";
          outcome.message = e.what();
        }
        {
          std::lock_guard<std::mutex> lock(mutex);
          finished.emplace_back(index, std::move(outcome));
        }
        ready.notify_one();
      }
    });
  std::exception_ptr callback_error;
  std::size_t expected = count;  // shrinks to the tasks already started when a callback throws
  for (std::size_t reported = 0; reported < expected; ++reported) {
    std::unique_lock<std::mutex> lock(mutex);
    ready.wait(lock, [&] { return !finished.empty(); });
    auto item = std::move(finished.front());
    finished.pop_front();
    lock.unlock();
    if (callback_error) continue;
    try {
      on_done(item.first, std::move(item.second));
    } catch (...) {
      callback_error = std::current_exception();
      std::lock_guard<std::mutex> stop(mutex);
      expected = next;  // started so far; nothing new starts
      next = count;
    }
  }
  for (auto& thread : pool) thread.join();
  if (callback_error) std::rethrow_exception(callback_error);
}

// ---- threads ---------------------------------------------------------------------------------

ThreadBackend::ThreadBackend(std::vector<dem::Scene> scenes, int threads)
    : scenes_(std::move(scenes)), threads_(threads > 0 ? threads : hardware_threads()) {
  for (const auto& scene : scenes_) hashes_.push_back(dem::scene_hash(scene));
}

std::string ThreadBackend::model_hash(std::size_t case_index) const { return hashes_.at(case_index); }

void ThreadBackend::run(const std::vector<SimulationTask>& tasks, const OutcomeCallback& on_done) {
  run_pool(
      tasks.size(), threads_,
      [&](std::size_t i) { return simulate_with_parameters(scenes_.at(tasks[i].case_index), tasks[i].params); },
      on_done);
}

// ---- external command ------------------------------------------------------------------------

std::vector<std::string> command_parameter_placeholders(const std::string& command) {
  std::vector<std::string> names;
  for (const auto& name : placeholder_names(split_command_line(command)))
    if (name != "output" && name != "workdir" && name != "case" && name != "scene") names.push_back(name);
  return names;
}

void CommandBackendOptions::Validate() const {
  for (const auto& name : command_parameter_placeholders(command)) {
    if (std::find(parameter_names.begin(), parameter_names.end(), name) == parameter_names.end()) {
      std::string known = "output, workdir, case, scene";
      for (const auto& p : parameter_names) known += ", " + p;
      throw std::invalid_argument("command template: unknown placeholder {" + name + "} (known: " + known + ")");
    }
  }
  const auto names = placeholder_names(split_command_line(command));
  if (std::find(names.begin(), names.end(), "output") == names.end())
    throw std::invalid_argument("command template must contain {output} (the CSV the program writes): " + command);
  if (!(timeout_s >= 0)) throw std::invalid_argument("command timeout must be >= 0 s, got " + std::to_string(timeout_s));
  if (work_root.empty()) throw std::invalid_argument("command backend: empty work_root");
  if (max_output_bytes <= 0)
    throw std::invalid_argument("command backend: max_output_bytes must be > 0, got " +
                                std::to_string(max_output_bytes));
  if (case_names.empty()) throw std::invalid_argument("command backend: no cases");
}

CommandBackend::CommandBackend(CommandBackendOptions options)
    : options_(std::move(options)), parallel_(options_.parallel > 0 ? options_.parallel : hardware_threads()) {
  options_.Validate();
  words_ = split_command_line(options_.command);
  fs::create_directories(options_.work_root);
}

std::string CommandBackend::model_hash(std::size_t case_index) const {
  std::string scene_text;
  const std::string& scene_file = options_.scene_files.size() > case_index ? options_.scene_files[case_index] : "";
  if (!scene_file.empty()) {
    std::ifstream in(scene_file, std::ios::binary);
    std::ostringstream buffer;
    buffer << in.rdbuf();
    scene_text = buffer.str();
  }
  return hash_text("command\n" + options_.command + "\n" + options_.case_names.at(case_index) + "\n" + scene_text);
}

namespace {
// The last max_chars characters of a file (reads no more than that), newlines shown as '|'.
std::string tail_of_file(const std::string& path, std::size_t max_chars) {
  std::ifstream in(path, std::ios::binary | std::ios::ate);
  if (!in) return {};
  const std::streamoff size = in.tellg();
  const std::streamoff from = size > static_cast<std::streamoff>(max_chars) ? size - static_cast<std::streamoff>(max_chars) : 0;
  in.seekg(from);
  std::string text(static_cast<size_t>(size - from), '\0');
  in.read(text.data(), static_cast<std::streamsize>(text.size()));
  text.resize(static_cast<size_t>(in.gcount()));
  while (!text.empty() && (text.back() == '\n' || text.back() == '\r' || text.back() == ' ')) text.pop_back();
  if (from > 0) text = "..." + text;
  for (auto& c : text)
    if (c == '\n') c = '|';
  return text;
}

std::string format_bytes(long long bytes) {
  char buffer[64];
  if (bytes >= (1ll << 20))
    std::snprintf(buffer, sizeof buffer, "%lld bytes (%.1f MiB)", bytes, static_cast<double>(bytes) / (1 << 20));
  else
    std::snprintf(buffer, sizeof buffer, "%lld bytes", bytes);
  return buffer;
}

bool non_finite_cell(std::string cell) {
  while (!cell.empty() && (cell.back() == ' ' || cell.back() == '\r' || cell.back() == '"')) cell.pop_back();
  size_t start = 0;
  while (start < cell.size() && (cell[start] == ' ' || cell[start] == '"')) ++start;
  cell = cell.substr(start);
  if (cell.empty()) return true;
  char* end = nullptr;
  const double value = std::strtod(cell.c_str(), &end);
  if (end == cell.c_str()) {
    for (auto& c : cell) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    return cell == "na" || cell == "n/a";
  }
  return *end == '\0' && !std::isfinite(value);
}

// The first data line of `path` whose cell in column `column` (0-based, of `columns`) is NaN,
// empty or infinite: "line 12, column 'force': non-finite value 'nan'". Falls back to the row.
std::string locate_non_finite(const std::string& path, size_t column, size_t columns, const std::string& name,
                              size_t row, double value) {
  std::ifstream in(path, std::ios::binary);
  std::string line;
  for (size_t number = 1; std::getline(in, line); ++number) {
    std::vector<std::string> cells(1);
    for (char c : line) {
      if (c == ',' || c == ';' || c == '\t') cells.emplace_back();
      else cells.back() += c;
    }
    if (cells.size() != columns || !non_finite_cell(cells[column])) continue;
    std::string cell = cells[column];
    while (!cell.empty() && cell.back() == '\r') cell.pop_back();
    return "line " + std::to_string(number) + ", column '" + name + "': non-finite value '" + cell + "'";
  }
  return "data row " + std::to_string(row + 1) + ", column '" + name + "': non-finite value '" + format_number(value, 6) + "'";
}
}  // namespace

SimulationOutcome CommandBackend::run_one(const SimulationTask& task) const {
  SimulationOutcome out;
  const std::string& case_name = options_.case_names.at(task.case_index);
  const fs::path workdir = fs::absolute(fs::path(options_.work_root) /
                                        (case_name + "-" + hash_text(parameter_key(task.params))));
  std::error_code ec;
  fs::remove_all(workdir, ec);
  fs::create_directories(workdir, ec);
  if (ec) {
    out.message = "cannot create run folder " + workdir.string() + ": " + ec.message();
    return out;
  }
  const std::string output = (workdir / "output.csv").string();
  std::map<std::string, std::string> values{{"output", output},
                                            {"workdir", workdir.string()},
                                            {"case", case_name},
                                            {"scene", options_.scene_files.size() > task.case_index
                                                          ? options_.scene_files[task.case_index]
                                                          : std::string()}};
  for (const auto& [name, value] : task.params) values[name] = format_number(value, round_trip_digits);
  ProcessOptions process;
  try {
    process.argv = expand_placeholders(words_, values);
  } catch (const std::exception& e) {
    out.message = e.what();
    return out;
  }
  process.working_directory = workdir.string();
  process.timeout_s = options_.timeout_s;
  process.stdout_path = (workdir / "stdout.txt").string();
  process.stderr_path = (workdir / "stderr.txt").string();
  process.max_file_bytes = options_.max_output_bytes;
  const ProcessResult result = run_process(process);
  out.wall_time_s = result.wall_time_s;
  out.details = {{"command", process.argv}, {"workdir", workdir.string()}, {"process_status", to_string(result.status)},
                 {"leftover_processes", result.leftover_processes}};
  auto fail = [&](const std::string& why) {
    out.status = "failed";
    out.curves = {};
    out.message = why;
    const std::string err = tail_of_file(process.stderr_path, 300);
    if (!err.empty()) out.message += "; stderr: " + err;
    return out;
  };
  if (!result.ok()) {
    std::string why = "external command " + result.message;
    if (result.status == ProcessStatus::signalled && result.signal == SIGXFSZ)
      why += ": a file it wrote reached the limit of " + format_bytes(options_.max_output_bytes) +
             " (backend.max_output_mb)";
    return fail(why);
  }
  if (!fs::exists(output)) return fail("external command exited 0 but wrote no output file " + output);
  const auto size = static_cast<long long>(fs::file_size(output, ec));
  if (ec) return fail("external command output " + output + ": cannot read its size: " + ec.message());
  if (size == 0) return fail("external command exited 0 but its output file " + output + " is empty");
  if (size >= options_.max_output_bytes)
    return fail("external command output " + output + " is " + format_bytes(size) + ", at or over the limit of " +
                format_bytes(options_.max_output_bytes) + " (backend.max_output_mb); not read");
  try {
    out.curves = smoothing::read_curve(output);
    out.curves.column("force");  // throws naming the columns when it is missing
  } catch (const std::exception& e) {
    return fail(std::string("external command output unreadable: ") + e.what());
  }
  const auto& columns = out.curves.columns;
  for (size_t c = 0; c < columns.size(); ++c)
    for (size_t r = 0; r < columns[c].values.size(); ++r)
      if (!std::isfinite(columns[c].values[r]))
        return fail("external command output " + output + ": " +
                    locate_non_finite(output, c, columns.size(), columns[c].name, r, columns[c].values[r]));
  if (result.leftover_processes > 0)
    out.message = "the program left " + std::to_string(result.leftover_processes) +
                  " process(es) running after it exited; killed";
  out.status = "completed";
  return out;
}

void CommandBackend::run(const std::vector<SimulationTask>& tasks, const OutcomeCallback& on_done) {
  run_pool(tasks.size(), parallel_, [&](std::size_t i) { return run_one(tasks[i]); }, on_done);
}

}  // namespace demcal::pipelines
