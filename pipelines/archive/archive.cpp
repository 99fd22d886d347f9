#include "demcal/pipelines/archive.hpp"

#include <sqlite3.h>
#include <unistd.h>

#include <filesystem>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <cstdlib>
#include <iostream>
#include <thread>

namespace demcal::pipelines {

namespace fs = std::filesystem;

namespace {

constexpr int kSchemaVersion = 1;

// Another process writing the same archive holds its write lock for one short transaction at a
// time. SQLite's busy handler waits up to kBusyTimeoutMs per attempt; a statement that still finds
// the archive locked is retried, with growing pauses, until kMaxBusyWait has passed in all.
constexpr int kBusyTimeoutMs = 10000;
constexpr std::chrono::seconds kMaxBusyWait{120};

bool is_busy(int rc) { return (rc & 0xff) == SQLITE_BUSY || (rc & 0xff) == SQLITE_LOCKED; }

// Calls attempt() until it returns something other than BUSY/LOCKED or the bounded wait is over.
template <class Attempt>
int with_busy_retry(Attempt attempt) {
  const auto deadline = std::chrono::steady_clock::now() + kMaxBusyWait;
  auto pause = std::chrono::milliseconds(5);
  for (;;) {
    const int rc = attempt();
    if (!is_busy(rc) || std::chrono::steady_clock::now() >= deadline) return rc;
    std::this_thread::sleep_for(pause);
    pause = std::min(pause * 2, std::chrono::milliseconds(200));
  }
}

// Testing aid for crash-safety soaks: with DEMCAL_ARCHIVE_WRITE_PAUSE_MS=N set, every write
// transaction announces itself on stderr ("demcal-archive: write K begins" / "... ends") and holds
// its transaction open N ms before COMMIT, so that a kill -9 can be aimed inside a write. Unset
// (the default): no effect. Returns -1 when unset.
int write_pause_ms() {
  static const int ms = [] {
    const char* text = std::getenv("DEMCAL_ARCHIVE_WRITE_PAUSE_MS");
    return text ? std::max(0, std::atoi(text)) : -1;
  }();
  return ms;
}

std::string utc_now() {
  const std::time_t now = std::time(nullptr);
  std::tm tm{};
  gmtime_r(&now, &tm);
  char buffer[32];
  std::strftime(buffer, sizeof buffer, "%Y-%m-%dT%H:%M:%SZ", &tm);
  return buffer;
}

// A prepared statement that finalises itself; errors name the archive file and the SQL.
class Statement {
 public:
  Statement(sqlite3* db, const std::string& path, const char* sql) : db_(db), path_(path), sql_(sql) {
    if (sqlite3_prepare_v2(db, sql, -1, &stmt_, nullptr) != SQLITE_OK) fail("prepare");
  }
  ~Statement() { sqlite3_finalize(stmt_); }
  Statement(const Statement&) = delete;
  Statement& operator=(const Statement&) = delete;

  void bind(int i, const std::string& text) {
    check(sqlite3_bind_text(stmt_, i, text.data(), static_cast<int>(text.size()), SQLITE_TRANSIENT));
  }
  void bind_blob(int i, const std::string& bytes) {
    check(sqlite3_bind_blob(stmt_, i, bytes.data(), static_cast<int>(bytes.size()), SQLITE_TRANSIENT));
  }
  void bind(int i, double value) {
    check(std::isnan(value) ? sqlite3_bind_null(stmt_, i) : sqlite3_bind_double(stmt_, i, value));
  }
  void bind(int i, std::int64_t value) { check(sqlite3_bind_int64(stmt_, i, value)); }
  void bind(int i, int value) { check(sqlite3_bind_int(stmt_, i, value)); }

  // true while rows come; false at the end.
  bool step() {
    const int rc = with_busy_retry([&] {
      const int attempt = sqlite3_step(stmt_);
      if (is_busy(attempt)) sqlite3_reset(stmt_);
      return attempt;
    });
    if (rc == SQLITE_ROW) return true;
    if (rc == SQLITE_DONE) return false;
    fail("step");
    return false;
  }
  std::string text(int col) const {
    const auto* p = reinterpret_cast<const char*>(sqlite3_column_text(stmt_, col));
    return p ? std::string(p, sqlite3_column_bytes(stmt_, col)) : std::string();
  }
  std::string blob(int col) const {
    const auto* p = static_cast<const char*>(sqlite3_column_blob(stmt_, col));
    return p ? std::string(p, sqlite3_column_bytes(stmt_, col)) : std::string();
  }
  double real(int col) const {
    return sqlite3_column_type(stmt_, col) == SQLITE_NULL ? std::numeric_limits<double>::quiet_NaN()
                                                          : sqlite3_column_double(stmt_, col);
  }
  std::int64_t integer(int col) const { return sqlite3_column_int64(stmt_, col); }

 private:
  void check(int rc) {
    if (rc != SQLITE_OK) fail("bind");
  }
  [[noreturn]] void fail(const char* what) {
    const int rc = sqlite3_errcode(db_);
    throw ArchiveError(path_ + ": SQLite " + what + " failed (" + sqlite3_errmsg(db_) + ")" +
                       (is_busy(rc) ? " after waiting " + std::to_string(kMaxBusyWait.count()) +
                                          " s for another process to release the archive"
                                    : std::string()) +
                       " in: " + sql_);
  }
  sqlite3* db_;
  const std::string& path_;
  const char* sql_;
  sqlite3_stmt* stmt_ = nullptr;
};

nlohmann::json params_to_json(const std::map<std::string, double>& params) {
  nlohmann::json j = nlohmann::json::object();
  for (const auto& [name, value] : params) j[name] = value;
  return j;
}


std::vector<std::string> json_strings(const std::string& text) {
  std::vector<std::string> out;
  if (text.empty()) return out;
  for (const auto& item : nlohmann::json::parse(text)) out.push_back(item.get<std::string>());
  return out;
}

}  // namespace

std::string parameter_key(const std::map<std::string, double>& params) {
  std::string key;
  for (const auto& [name, value] : params) {
    char buffer[64];
    std::snprintf(buffer, sizeof buffer, "%a", value);
    if (!key.empty()) key += ';';
    key += name + "=" + buffer;
  }
  return key;
}

// Parameters travel as their exact key text next to the readable JSON, so they read back
// bit-identical whatever the JSON printer does with the digits.
std::map<std::string, double> params_from_key(const std::string& key) {
  std::map<std::string, double> params;
  size_t start = 0;
  while (start < key.size()) {
    size_t end = key.find(';', start);
    if (end == std::string::npos) end = key.size();
    const std::string item = key.substr(start, end - start);
    const size_t eq = item.find('=');
    if (eq != std::string::npos) params[item.substr(0, eq)] = std::strtod(item.c_str() + eq + 1, nullptr);
    start = end + 1;
  }
  return params;
}

std::string hash_text(const std::string& text) {
  std::uint64_t hash = 1469598103934665603ull;
  for (unsigned char c : text) {
    hash ^= c;
    hash *= 1099511628211ull;
  }
  char buffer[17];
  std::snprintf(buffer, sizeof buffer, "%016llx", static_cast<unsigned long long>(hash));
  return buffer;
}

std::string pack_curve_values(const smoothing::Curve& curve) {
  std::string bytes;
  const size_t rows = curve.rows();
  bytes.reserve(rows * curve.columns.size() * sizeof(double));
  for (const auto& column : curve.columns) {
    if (column.values.size() != rows)
      throw ArchiveError("curve " + curve.source + ": column '" + column.name + "' has " +
                         std::to_string(column.values.size()) + " values, expected " + std::to_string(rows));
    bytes.append(reinterpret_cast<const char*>(column.values.data()), rows * sizeof(double));
  }
  return bytes;
}

smoothing::Curve unpack_curve(const std::vector<std::string>& names, const std::vector<std::string>& units,
                              const std::string& packed, const std::string& source) {
  smoothing::Curve curve;
  curve.source = source;
  if (names.empty()) return curve;
  const size_t per_column = packed.size() / sizeof(double) / names.size();
  if (per_column * names.size() * sizeof(double) != packed.size())
    throw ArchiveError(source + ": curve data of " + std::to_string(packed.size()) +
                       " bytes does not divide into " + std::to_string(names.size()) + " columns");
  for (size_t c = 0; c < names.size(); ++c) {
    smoothing::Column column;
    column.name = names[c];
    column.unit = c < units.size() ? units[c] : "";
    column.values.resize(per_column);
    std::memcpy(column.values.data(), packed.data() + c * per_column * sizeof(double), per_column * sizeof(double));
    curve.columns.push_back(std::move(column));
  }
  return curve;
}

RunArchive::RunArchive(const std::string& path) : path_(path) {
  if (sqlite3_open_v2(path.c_str(), &db_, SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE | SQLITE_OPEN_FULLMUTEX,
                      nullptr) != SQLITE_OK) {
    std::string why = db_ ? sqlite3_errmsg(db_) : "out of memory";
    sqlite3_close(db_);
    db_ = nullptr;
    // Say what is wrong with the place, where it is something simple.
    std::error_code ec;
    const fs::path folder = fs::absolute(fs::path(path), ec).parent_path();
    if (!fs::exists(folder, ec))
      why += ": the folder " + folder.string() + " does not exist";
    else if (!fs::exists(path, ec) && ::access(folder.c_str(), W_OK) != 0)
      why += ": the folder " + folder.string() + " is not writable";
    else if (fs::exists(path, ec) && ::access(path.c_str(), R_OK | W_OK) != 0)
      why += ": the file is not readable and writable";
    throw ArchiveError(path + ": cannot open the run archive (" + why + ")");
  }
  try {
    open_schema();
  } catch (...) {
    sqlite3_close(db_);
    db_ = nullptr;
    throw;
  }
}

void RunArchive::open_schema() {
  sqlite3_busy_timeout(db_, kBusyTimeoutMs);
  try {
    exec("PRAGMA journal_mode=WAL");
  } catch (const ArchiveError&) {
    const int rc = sqlite3_errcode(db_);
    if (rc == SQLITE_NOTADB || rc == SQLITE_CORRUPT)
      throw ArchiveError(path_ + ": not a demcal run archive: not an SQLite database, or a damaged one (" +
                         sqlite3_errmsg(db_) + "); move it away or name another file with --archive");
    throw;
  }
  exec("PRAGMA synchronous=NORMAL");  // with WAL: durable against a killed process
  exec("PRAGMA foreign_keys=ON");
  // A database with tables but no demcal schema version belongs to something else: never add ours.
  {
    Statement tables(db_, path_, "SELECT name FROM sqlite_master WHERE type='table' ORDER BY name");
    std::string names;
    bool has_meta = false;
    while (tables.step()) {
      names += (names.empty() ? "" : ", ") + tables.text(0);
      has_meta = has_meta || tables.text(0) == "meta";
    }
    bool versioned = false;
    if (has_meta) {
      Statement version(db_, path_, "SELECT COUNT(*) FROM meta WHERE key='schema_version'");
      versioned = version.step() && version.integer(0) > 0;
    }
    if (!names.empty() && !versioned)
      throw ArchiveError(path_ + ": not a demcal run archive: an SQLite database with tables " + names +
                         " and no demcal schema version; name another file with --archive");
  }
  // Two processes may create the archive at once: the schema goes in one write transaction.
  Transaction transaction(*this);
  exec(R"sql(
    CREATE TABLE IF NOT EXISTS meta(key TEXT PRIMARY KEY, value TEXT NOT NULL);
    CREATE TABLE IF NOT EXISTS runs(
      id INTEGER PRIMARY KEY, model_hash TEXT NOT NULL, param_key TEXT NOT NULL,
      params_json TEXT NOT NULL, code_version TEXT NOT NULL, backend TEXT NOT NULL,
      status TEXT NOT NULL, message TEXT NOT NULL, wall_time_s REAL,
      curve_columns TEXT NOT NULL, curve_units TEXT NOT NULL, curve_data BLOB,
      details_json TEXT NOT NULL, created_at TEXT NOT NULL,
      UNIQUE(model_hash, param_key));
    CREATE TABLE IF NOT EXISTS fitness(
      run_id INTEGER NOT NULL REFERENCES runs(id), objective_key TEXT NOT NULL,
      objective INTEGER NOT NULL, objective1 REAL, objective2 REAL, fitness REAL,
      channels_json TEXT NOT NULL, wall_time_s REAL,
      PRIMARY KEY(run_id, objective_key));
    CREATE TABLE IF NOT EXISTS campaigns(
      id INTEGER PRIMARY KEY, name TEXT NOT NULL, config_key TEXT NOT NULL,
      config_json TEXT NOT NULL, code_version TEXT NOT NULL, created_at TEXT NOT NULL);
    CREATE INDEX IF NOT EXISTS campaigns_by_key ON campaigns(config_key);
    CREATE TABLE IF NOT EXISTS iterations(
      campaign_id INTEGER NOT NULL REFERENCES campaigns(id), iteration INTEGER NOT NULL,
      optimiser_state TEXT NOT NULL, best_fitness REAL, evaluations INTEGER NOT NULL,
      wall_time_s REAL, created_at TEXT NOT NULL,
      PRIMARY KEY(campaign_id, iteration));
    CREATE TABLE IF NOT EXISTS evaluations(
      campaign_id INTEGER NOT NULL REFERENCES campaigns(id), iteration INTEGER NOT NULL,
      position INTEGER NOT NULL, params_json TEXT NOT NULL, param_key TEXT NOT NULL,
      run_ids_json TEXT NOT NULL, fitness REAL,
      PRIMARY KEY(campaign_id, iteration, position));
)sql");
  exec("INSERT OR IGNORE INTO meta(key, value) VALUES('schema_version', '" + std::to_string(kSchemaVersion) + "')");
  transaction.commit();
  Statement version(db_, path_, "SELECT value FROM meta WHERE key='schema_version'");
  if (version.step() && version.text(0) != std::to_string(kSchemaVersion))
    throw ArchiveError(path_ + ": archive schema version " + version.text(0) + ", this demcal reads " +
                       std::to_string(kSchemaVersion));
}

RunArchive::Transaction::Transaction(RunArchive& archive) : archive_(archive) {
  archive_.exec("BEGIN IMMEDIATE");
  if (write_pause_ms() >= 0) {
    static std::atomic<long> writes{0};
    number_ = ++writes;
    std::cerr << "demcal-archive: write " << number_ << " begins\n" << std::flush;
  }
}

void RunArchive::Transaction::commit() {
  if (const int ms = write_pause_ms(); ms > 0) std::this_thread::sleep_for(std::chrono::milliseconds(ms));
  archive_.exec("COMMIT");
  committed_ = true;
  if (number_ > 0) std::cerr << "demcal-archive: write " << number_ << " ends\n" << std::flush;
}

RunArchive::Transaction::~Transaction() {
  if (!committed_) sqlite3_exec(archive_.db_, "ROLLBACK", nullptr, nullptr, nullptr);
}

RunArchive::~RunArchive() { sqlite3_close(db_); }

void RunArchive::exec(const std::string& sql) const {
  char* error = nullptr;
  const int rc = with_busy_retry([&] {
    sqlite3_free(error);
    error = nullptr;
    return sqlite3_exec(db_, sql.c_str(), nullptr, nullptr, &error);
  });
  if (rc != SQLITE_OK) {
    const std::string why = error ? error : sqlite3_errstr(rc);
    sqlite3_free(error);
    throw ArchiveError(path_ + ": SQLite failed (" + why + ")" +
                       (is_busy(rc) ? " after waiting " + std::to_string(kMaxBusyWait.count()) +
                                          " s for another process to release the archive"
                                    : std::string()) +
                       " in: " + sql.substr(0, 120));
  }
}

std::int64_t RunArchive::insert_run(const RunRecord& run) {
  const std::string key = parameter_key(run.params);
  Transaction transaction(*this);
  {
    Statement insert(db_, path_,
                     "INSERT OR IGNORE INTO runs(model_hash, param_key, params_json, code_version, backend,"
                     " status, message, wall_time_s, curve_columns, curve_units, curve_data, details_json,"
                     " created_at) VALUES(?,?,?,?,?,?,?,?,?,?,?,?,?)");
    nlohmann::json names = nlohmann::json::array(), units = nlohmann::json::array();
    for (const auto& column : run.curves.columns) {
      names.push_back(column.name);
      units.push_back(column.unit);
    }
    insert.bind(1, run.model_hash);
    insert.bind(2, key);
    insert.bind(3, params_to_json(run.params).dump());
    insert.bind(4, run.code_version);
    insert.bind(5, run.backend);
    insert.bind(6, run.status);
    insert.bind(7, run.message);
    insert.bind(8, run.wall_time_s);
    insert.bind(9, names.dump());
    insert.bind(10, units.dump());
    insert.bind_blob(11, pack_curve_values(run.curves));
    insert.bind(12, run.details.dump());
    insert.bind(13, run.created_at.empty() ? utc_now() : run.created_at);
    insert.step();
  }
  Statement select(db_, path_, "SELECT id FROM runs WHERE model_hash=? AND param_key=?");
  select.bind(1, run.model_hash);
  select.bind(2, key);
  if (!select.step()) throw ArchiveError(path_ + ": run just inserted is missing");
  const std::int64_t id = select.integer(0);
  transaction.commit();
  return id;
}

namespace {
constexpr const char* kRunColumns =
    "SELECT id, model_hash, param_key, code_version, backend, status, message, wall_time_s,"
    " curve_columns, curve_units, curve_data, details_json, created_at FROM runs ";

// The first eight columns of kRunColumns, which every run query starts with.
RunRecord read_run_header(const Statement& s) {
  RunRecord run;
  run.id = s.integer(0);
  run.model_hash = s.text(1);
  run.params = params_from_key(s.text(2));
  run.code_version = s.text(3);
  run.backend = s.text(4);
  run.status = s.text(5);
  run.message = s.text(6);
  run.wall_time_s = s.real(7);
  return run;
}

RunRecord read_run(const Statement& s, const std::string& path) {
  RunRecord run = read_run_header(s);
  run.curves = unpack_curve(json_strings(s.text(8)), json_strings(s.text(9)), s.blob(10),
                            path + ": run " + std::to_string(run.id));
  run.details = nlohmann::json::parse(s.text(11));
  run.created_at = s.text(12);
  return run;
}
}  // namespace

std::optional<RunRecord> RunArchive::find_run(const std::string& model_hash,
                                              const std::map<std::string, double>& params) const {
  Statement s(db_, path_, (std::string(kRunColumns) + "WHERE model_hash=? AND param_key=?").c_str());
  s.bind(1, model_hash);
  s.bind(2, parameter_key(params));
  if (!s.step()) return std::nullopt;
  return read_run(s, path_);
}

std::optional<RunRecord> RunArchive::run(std::int64_t id) const {
  Statement s(db_, path_, (std::string(kRunColumns) + "WHERE id=?").c_str());
  s.bind(1, id);
  if (!s.step()) return std::nullopt;
  return read_run(s, path_);
}

std::int64_t RunArchive::run_count() const {
  Statement s(db_, path_, "SELECT COUNT(*) FROM runs");
  s.step();
  return s.integer(0);
}

std::string RunArchive::integrity_check() const {
  Statement s(db_, path_, "PRAGMA integrity_check");
  std::string out;
  while (s.step()) out += (out.empty() ? "" : "\n") + s.text(0);
  return out;
}

std::vector<RunRecord> RunArchive::runs_with_status(const std::string& status) const {
  Statement s(db_, path_,
              "SELECT id, model_hash, param_key, code_version, backend, status, message, wall_time_s,"
              " details_json, created_at FROM runs WHERE status=? ORDER BY id");
  s.bind(1, status);
  std::vector<RunRecord> out;
  while (s.step()) {
    RunRecord run = read_run_header(s);
    run.details = nlohmann::json::parse(s.text(8));
    run.created_at = s.text(9);
    out.push_back(std::move(run));
  }
  return out;
}

std::int64_t RunArchive::max_run_id() const {
  Statement s(db_, path_, "SELECT COALESCE(MAX(id), 0) FROM runs");
  s.step();
  return s.integer(0);
}

namespace {

// The rows of a query selecting (runs.id, runs.param_key, runs.status[, fitness]).
std::vector<RunFitness> run_fitness_rows(Statement& s, bool with_fitness) {
  std::vector<RunFitness> out;
  while (s.step()) {
    RunFitness r;
    r.run_id = s.integer(0);
    r.params = params_from_key(s.text(1));
    r.status = s.text(2);
    if (with_fitness) r.fitness = s.real(3);
    out.push_back(std::move(r));
  }
  return out;
}

}  // namespace

std::vector<RunFitness> RunArchive::run_fitness(const std::string& model_hash, const std::string& objective_key,
                                                std::int64_t max_run_id) const {
  Statement s(db_, path_,
              "SELECT runs.id, runs.param_key, runs.status, fitness.fitness FROM runs JOIN fitness"
              " ON fitness.run_id = runs.id WHERE runs.model_hash=? AND fitness.objective_key=? AND runs.id<=?"
              " ORDER BY runs.id");
  s.bind(1, model_hash);
  s.bind(2, objective_key);
  s.bind(3, max_run_id);
  return run_fitness_rows(s, true);
}

std::vector<RunFitness> RunArchive::unscored_runs(const std::string& model_hash, const std::string& objective_key) const {
  Statement s(db_, path_,
              "SELECT runs.id, runs.param_key, runs.status FROM runs WHERE runs.model_hash=? AND runs.status<>'cancelled'"
              " AND NOT EXISTS (SELECT 1 FROM fitness WHERE fitness.run_id = runs.id AND fitness.objective_key=?)"
              " ORDER BY runs.id");
  s.bind(1, model_hash);
  s.bind(2, objective_key);
  return run_fitness_rows(s, false);
}

std::vector<RunArchive::ModelObjective> RunArchive::model_objectives() const {
  Statement s(db_, path_,
              "SELECT runs.model_hash, fitness.objective_key, COUNT(*) AS n FROM runs JOIN fitness"
              " ON fitness.run_id = runs.id GROUP BY runs.model_hash, fitness.objective_key"
              " ORDER BY n DESC, runs.model_hash, fitness.objective_key");
  std::vector<ModelObjective> out;
  while (s.step()) out.push_back({s.text(0), s.text(1), s.integer(2)});
  return out;
}

std::vector<CampaignRecord> RunArchive::campaigns() const {
  Statement s(db_, path_,
              "SELECT id, name, config_key, config_json, code_version, created_at FROM campaigns ORDER BY id");
  std::vector<CampaignRecord> out;
  while (s.step()) {
    CampaignRecord c;
    c.id = s.integer(0);
    c.name = s.text(1);
    c.config_key = s.text(2);
    c.config = nlohmann::json::parse(s.text(3));
    c.code_version = s.text(4);
    c.created_at = s.text(5);
    out.push_back(std::move(c));
  }
  return out;
}

void RunArchive::put_fitness(const FitnessRecord& f) {
  Transaction transaction(*this);
  Statement s(db_, path_,
              "INSERT OR REPLACE INTO fitness(run_id, objective_key, objective, objective1, objective2,"
              " fitness, channels_json, wall_time_s) VALUES(?,?,?,?,?,?,?,?)");
  s.bind(1, f.run_id);
  s.bind(2, f.objective_key);
  s.bind(3, f.objective);
  s.bind(4, f.objective1);
  s.bind(5, f.objective2);
  s.bind(6, f.fitness);
  s.bind(7, f.channels.dump());
  s.bind(8, f.wall_time_s);
  s.step();
  transaction.commit();
}

std::optional<FitnessRecord> RunArchive::find_fitness(std::int64_t run_id, const std::string& objective_key) const {
  Statement s(db_, path_,
              "SELECT objective, objective1, objective2, fitness, channels_json, wall_time_s FROM fitness"
              " WHERE run_id=? AND objective_key=?");
  s.bind(1, run_id);
  s.bind(2, objective_key);
  if (!s.step()) return std::nullopt;
  FitnessRecord f;
  f.run_id = run_id;
  f.objective_key = objective_key;
  f.objective = static_cast<int>(s.integer(0));
  f.objective1 = s.real(1);
  f.objective2 = s.real(2);
  f.fitness = s.real(3);
  f.channels = nlohmann::json::parse(s.text(4));
  f.wall_time_s = s.real(5);
  return f;
}

std::int64_t RunArchive::create_campaign(const CampaignRecord& c) {
  Transaction transaction(*this);
  Statement s(db_, path_,
              "INSERT INTO campaigns(name, config_key, config_json, code_version, created_at) VALUES(?,?,?,?,?)");
  s.bind(1, c.name);
  s.bind(2, c.config_key);
  s.bind(3, c.config.dump());
  s.bind(4, c.code_version);
  s.bind(5, c.created_at.empty() ? utc_now() : c.created_at);
  s.step();
  const std::int64_t id = sqlite3_last_insert_rowid(db_);
  transaction.commit();
  return id;
}

std::optional<CampaignRecord> RunArchive::latest_campaign(const std::string& config_key) const {
  Statement s(db_, path_,
              "SELECT id, name, config_json, code_version, created_at FROM campaigns WHERE config_key=?"
              " ORDER BY id DESC LIMIT 1");
  s.bind(1, config_key);
  if (!s.step()) return std::nullopt;
  CampaignRecord c;
  c.id = s.integer(0);
  c.name = s.text(1);
  c.config_key = config_key;
  c.config = nlohmann::json::parse(s.text(2));
  c.code_version = s.text(3);
  c.created_at = s.text(4);
  return c;
}

void RunArchive::commit_iteration(const IterationRecord& it, const std::vector<EvaluationRecord>& evaluations) {
  Transaction transaction(*this);
  {
    for (const auto& e : evaluations) {
      Statement s(db_, path_,
                  "INSERT OR REPLACE INTO evaluations(campaign_id, iteration, position, params_json, param_key,"
                  " run_ids_json, fitness) VALUES(?,?,?,?,?,?,?)");
      s.bind(1, it.campaign_id);
      s.bind(2, it.iteration);
      s.bind(3, e.position);
      s.bind(4, params_to_json(e.params).dump());
      s.bind(5, parameter_key(e.params));
      s.bind(6, nlohmann::json(e.run_ids).dump());
      s.bind(7, e.fitness);
      s.step();
    }
    Statement s(db_, path_,
                "INSERT OR REPLACE INTO iterations(campaign_id, iteration, optimiser_state, best_fitness,"
                " evaluations, wall_time_s, created_at) VALUES(?,?,?,?,?,?,?)");
    s.bind(1, it.campaign_id);
    s.bind(2, it.iteration);
    s.bind(3, it.optimiser_state);
    s.bind(4, it.best_fitness);
    s.bind(5, it.evaluations);
    s.bind(6, it.wall_time_s);
    s.bind(7, it.created_at.empty() ? utc_now() : it.created_at);
    s.step();
  }
  transaction.commit();
}

namespace {
IterationRecord read_iteration(const Statement& s) {
  IterationRecord it;
  it.campaign_id = s.integer(0);
  it.iteration = static_cast<int>(s.integer(1));
  it.optimiser_state = s.text(2);
  it.best_fitness = s.real(3);
  it.evaluations = static_cast<int>(s.integer(4));
  it.wall_time_s = s.real(5);
  it.created_at = s.text(6);
  return it;
}
constexpr const char* kIterationColumns =
    "SELECT campaign_id, iteration, optimiser_state, best_fitness, evaluations, wall_time_s, created_at"
    " FROM iterations WHERE campaign_id=? ORDER BY iteration";
}  // namespace

std::optional<IterationRecord> RunArchive::last_iteration(std::int64_t campaign_id) const {
  Statement s(db_, path_, (std::string(kIterationColumns) + " DESC LIMIT 1").c_str());
  s.bind(1, campaign_id);
  if (!s.step()) return std::nullopt;
  return read_iteration(s);
}

std::vector<IterationRecord> RunArchive::iterations(std::int64_t campaign_id) const {
  Statement s(db_, path_, kIterationColumns);
  s.bind(1, campaign_id);
  std::vector<IterationRecord> out;
  while (s.step()) out.push_back(read_iteration(s));
  return out;
}

std::vector<EvaluationRecord> RunArchive::evaluations(std::int64_t campaign_id) const {
  Statement s(db_, path_,
              "SELECT iteration, position, param_key, run_ids_json, fitness FROM evaluations"
              " WHERE campaign_id=? ORDER BY iteration, position");
  s.bind(1, campaign_id);
  std::vector<EvaluationRecord> out;
  while (s.step()) {
    EvaluationRecord e;
    e.campaign_id = campaign_id;
    e.iteration = static_cast<int>(s.integer(0));
    e.position = static_cast<int>(s.integer(1));
    e.params = params_from_key(s.text(2));
    e.run_ids = nlohmann::json::parse(s.text(3)).get<std::vector<std::int64_t>>();
    e.fitness = s.real(4);
    out.push_back(std::move(e));
  }
  return out;
}

}  // namespace demcal::pipelines
