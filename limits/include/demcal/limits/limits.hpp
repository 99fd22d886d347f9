// Upper limits on every count and size that demcal takes from a user, so that a typo
// (`--voussoirs 2000000000`, a record interval of 1e-15 m, a 50 GB file named by mistake) is refused
// with a message before anything is allocated or run, instead of allocating without end or never
// returning. Each limit has a key, a default well above any real use, and a noun for the message.
//
// Raising one: `--limit KEY=N` on any demcal command (repeatable), or the environment variable
// DEMCAL_LIMITS="KEY=N,KEY=N" (read at first use; child processes such as MPI ranks and external
// simulators inherit it, and `--limit` exports what it sets there too). The keys, defaults and the
// messages are listed in docs/bad-input.md.
//
// A size that only echoes the length of the input itself (the entries of a JSON array, the cells of
// a row) is bounded by `file_bytes`; the limits below are the counts that multiply (blocks, rows,
// steps, evaluations) or that a short input can make huge.
#pragma once

#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace demcal::limits {

enum class Limit {
  blocks,              // blocks in a scene (a scene file's `blocks`, an arch's voussoirs, a wall's units)
  vertices_per_block,  // vertices of one block
  recorded_rows,       // rows one run records: actuator travel / record interval
  time_steps,          // explicit steps one run may take: simulated time / the first time step
  file_bytes,          // size of any file demcal reads (CSV, scene, campaign, study, model)
  curve_rows,          // data rows of one curve
  parameters,          // dimensions of a parameter space
  population,          // optimiser population (swarm, GA, NLopt's own)
  iterations,          // planned optimiser iterations
  evaluations,         // evaluations (simulations) of one search, polish or diagnosis stage
  workers,             // threads or programs at once (backends, fitness threads, LibTorch threads)
  network_weights,     // weights of a network or ensemble (smoother, surrogate curve model)
  epochs,              // training epochs of a network
  curve_points,        // points a curve is resampled to (smoother output, surrogate curves)
  training_rows,       // runs a surrogate trains on
  campaigns,           // campaigns of a study (methods x seeds)
};

struct LimitInfo {
  Limit limit;
  std::string_view key;   // "blocks": --limit blocks=N, DEMCAL_LIMITS=blocks=N
  std::string_view noun;  // "blocks", as in "2000000002 blocks"
  double default_value;
};

// Every limit, in enum order.
const std::vector<LimitInfo>& all_limits();
const LimitInfo& info(Limit limit);

// The limit in force (the default, DEMCAL_LIMITS, then --limit).
double value(Limit limit);

// True when `count` is above the limit (a NaN count is above every limit).
bool exceeds(Limit limit, double count);

// "2000000002 blocks exceed the limit of 100000 (limit 'blocks'; raise it with --limit blocks=N or
// DEMCAL_LIMITS=blocks=N)". The caller prefixes where the count came from (a flag with its value,
// a key path) and throws its own module's error.
std::string message(Limit limit, double count);

// A number as limit messages write it: whole numbers in full (2000000002), others in 6 significant
// digits (1e-15), for the subject the caller puts before message().
std::string number_text(double value);

// The message when `count` exceeds the limit, nothing otherwise.
std::optional<std::string> check(Limit limit, double count);

// Throws std::invalid_argument("SUBJECT: MESSAGE") when `count` exceeds the limit: for options
// structs whose Validate() reports with std::invalid_argument ("option population").
void require_within(Limit limit, double count, std::string_view subject);

// The message when the file at `path` is larger than `file_bytes`; nothing when it is within the
// limit or cannot be sized (the caller's open reports a missing file).
std::optional<std::string> check_file_size(const std::string& path);

// Sets one limit from "KEY=N" (N a positive number, 1e6 allowed). Throws std::invalid_argument
// naming the text, the known keys or the bad number. `export_to_environment` also writes every
// limit not at its default to DEMCAL_LIMITS, so that processes started afterwards inherit them.
void set_from_text(std::string_view key_equals_value, bool export_to_environment = false);

// Restores every default and reads DEMCAL_LIMITS again (tests).
void reset();

}  // namespace demcal::limits
