#include "demcal/pipelines/process.hpp"

#include "demcal/common/format.hpp"

#include <dirent.h>
#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/syscall.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>
#ifdef __linux__
#include <sys/prctl.h>
#endif

#include <cerrno>
#include <chrono>
#include <cstring>
#include <stdexcept>

namespace demcal::pipelines {

void ProcessOptions::Validate() const {
  if (argv.empty() || argv[0].empty())
    throw std::invalid_argument("process: empty command (no program to run)");
  if (!(timeout_s >= 0))
    throw std::invalid_argument("process: timeout_s must be >= 0, got " + std::to_string(timeout_s));
  if (max_file_bytes < 0)
    throw std::invalid_argument("process: max_file_bytes must be >= 0, got " + std::to_string(max_file_bytes));
}

std::string to_string(ProcessStatus status) {
  switch (status) {
    case ProcessStatus::exited: return "exited";
    case ProcessStatus::signalled: return "signalled";
    case ProcessStatus::timed_out: return "timed_out";
    case ProcessStatus::cancelled: return "cancelled";
    case ProcessStatus::failed_to_start: return "failed_to_start";
  }
  return "unknown";
}

namespace {

int open_output(const std::string& path) {
  if (path.empty()) return ::open("/dev/null", O_WRONLY | O_CLOEXEC);
  return ::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
}

// ---- the supervisor (runs between fork and _exit: async-signal-safe calls only) ----------------

// Messages from the supervisor to the caller: fixed-size records (atomic pipe writes).
enum SupervisorMessage : int {
  kStarted = 1,     // value: the program's pid (= its process group)
  kExecFailed = 2,  // value: errno of chdir/exec
  kExited = 3,      // value: the program's wait status
  kKilled = 4,      // the caller asked (timeout, cancel) or went away; the program was killed
  kLeftovers = 5,   // value: descendants still running after the program ended (killed)
};
struct Message {
  int kind;
  int value;
};

void send(int fd, int kind, int value) {
  const Message m{kind, value};
  ssize_t ignored = ::write(fd, &m, sizeof m);
  (void)ignored;
}

void sleep_ms(long ms) {
  timespec t{ms / 1000, (ms % 1000) * 1000000L};
  ::nanosleep(&t, nullptr);
}

// Appends the decimal digits of value to buffer at *at.
void append_number(char* buffer, int* at, long value) {
  char digits[24];
  int n = 0;
  do digits[n++] = static_cast<char>('0' + value % 10);
  while ((value /= 10) > 0);
  while (n > 0) buffer[(*at)++] = digits[--n];
}

// SIGKILLs every child of this process (the supervisor) listed in /proc/PID/task/PID/children
// (a single-threaded process: its one task lists them all); -1 when the kernel lacks that file.
int kill_listed_children(pid_t self) {
  char path[96] = "/proc/";
  int at = 6;
  append_number(path, &at, self);
  for (const char* c = "/task/"; *c; ++c) path[at++] = *c;
  append_number(path, &at, self);
  for (const char* c = "/children"; *c; ++c) path[at++] = *c;
  path[at] = '\0';
  const int fd = ::open(path, O_RDONLY | O_CLOEXEC);
  if (fd < 0) return -1;
  int killed = 0;
  long pid = 0;
  char buffer[1024];
  for (ssize_t got; (got = ::read(fd, buffer, sizeof buffer)) > 0;)
    for (ssize_t i = 0; i < got; ++i) {
      if (buffer[i] >= '0' && buffer[i] <= '9') {
        pid = pid * 10 + (buffer[i] - '0');
      } else {
        if (pid > 0 && ::kill(static_cast<pid_t>(pid), SIGKILL) == 0) ++killed;
        pid = 0;
      }
    }
  if (pid > 0 && ::kill(static_cast<pid_t>(pid), SIGKILL) == 0) ++killed;
  ::close(fd);
  return killed;
}

// SIGKILLs every process whose parent is this one (the supervisor); returns how many. Reads the
// kernel's list of children where it has one, else scans /proc/*/stat for the parent pid.
int kill_own_children(pid_t self) {
  if (const int killed = kill_listed_children(self); killed >= 0) return killed;
  const int dir = ::open("/proc", O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (dir < 0) return 0;
  int killed = 0;
  alignas(8) char buffer[8192];
  for (;;) {
    const long got = ::syscall(SYS_getdents64, dir, buffer, sizeof buffer);
    if (got <= 0) break;
    for (long offset = 0; offset < got;) {
      const auto* entry = reinterpret_cast<const dirent64*>(buffer + offset);
      offset += entry->d_reclen;
      pid_t pid = 0;
      const char* name = entry->d_name;
      if (*name < '1' || *name > '9') continue;
      for (; *name >= '0' && *name <= '9'; ++name) pid = pid * 10 + (*name - '0');
      if (*name != '\0' || pid == self) continue;
      // /proc/<pid>/stat: "pid (comm) state ppid ..."; comm may hold spaces and parentheses.
      char path[40] = "/proc/";
      char digits[16];
      int n = 0;
      for (pid_t v = pid; v > 0; v /= 10) digits[n++] = static_cast<char>('0' + v % 10);
      int p = 6;
      while (n > 0) path[p++] = digits[--n];
      const char tail[] = "/stat";
      for (char c : tail) path[p++] = c;
      const int fd = ::open(path, O_RDONLY | O_CLOEXEC);
      if (fd < 0) continue;
      char stat[512];
      const ssize_t len = ::read(fd, stat, sizeof stat - 1);
      ::close(fd);
      if (len <= 0) continue;
      stat[len] = '\0';
      const char* close_paren = nullptr;
      for (const char* c = stat; *c; ++c)
        if (*c == ')') close_paren = c;
      if (!close_paren || close_paren[1] != ' ' || close_paren[2] == '\0' || close_paren[3] != ' ') continue;
      pid_t ppid = 0;
      for (const char* c = close_paren + 4; *c >= '0' && *c <= '9'; ++c) ppid = ppid * 10 + (*c - '0');
      if (ppid == self && ::kill(pid, SIGKILL) == 0) ++killed;
    }
  }
  ::close(dir);
  return killed;
}

// Kills the program's group and every descendant re-parented here, reaping them, until the
// supervisor has no child left (or 30 s pass: a process stuck in the kernel). Returns the number
// of processes that were still running when the sweep began, besides the program itself.
int kill_everything(pid_t program, pid_t self, bool program_reaped, int* program_status) {
  int leftovers = 0;
  bool counted = false;
  for (int round = 0; round < 30000; ++round) {
    ::kill(-program, SIGKILL);
    const int killed = kill_own_children(self);
    if (!counted) {
      leftovers = killed - (program_reaped ? 0 : 1);
      counted = true;
    }
    bool any = false;
    for (;;) {
      int status = 0;
      const pid_t done = ::waitpid(-1, &status, WNOHANG);
      if (done > 0) {
        any = true;
        if (done == program && !program_reaped) {
          program_reaped = true;
          *program_status = status;
        }
        continue;
      }
      if (done < 0 && errno == ECHILD) return leftovers < 0 ? 0 : leftovers;
      break;
    }
    if (!any) sleep_ms(1);
  }
  return leftovers < 0 ? 0 : leftovers;
}

struct ChildSetup {
  char* const* argv;
  const char* workdir;
  int out_fd, err_fd, lifeline, report;
  long long max_file_bytes;
};

[[noreturn]] void supervise(const ChildSetup& setup) {
  ::setpgid(0, 0);
  struct sigaction ignore {};
  ignore.sa_handler = SIG_IGN;
  for (int sig : {SIGINT, SIGTERM, SIGHUP, SIGQUIT, SIGPIPE}) ::sigaction(sig, &ignore, nullptr);
  // SIGCHLD is blocked except inside ppoll(), so the end of a child wakes the wait at once and
  // never slips in between a check and the wait.
  struct sigaction wake {};
  wake.sa_handler = [](int) {};
  ::sigaction(SIGCHLD, &wake, nullptr);
  sigset_t none, only_child;
  sigemptyset(&none);
  sigemptyset(&only_child);
  sigaddset(&only_child, SIGCHLD);
  ::sigprocmask(SIG_SETMASK, &only_child, nullptr);
#ifdef __linux__
  ::prctl(PR_SET_CHILD_SUBREAPER, 1, 0, 0, 0);
#endif
  // Keep only what is needed at fixed numbers 3..6, close every other descriptor inherited from
  // the caller (another run's lifeline among them: its supervisor must see the caller go away).
  const int keep[4] = {setup.out_fd, setup.err_fd, setup.lifeline, setup.report};
  int moved[4];
  for (int i = 0; i < 4; ++i) moved[i] = ::fcntl(keep[i], F_DUPFD_CLOEXEC, 64);
  for (int i = 0; i < 4; ++i) {
    ::dup2(moved[i], 3 + i);
    ::fcntl(3 + i, F_SETFD, FD_CLOEXEC);
  }
#ifdef SYS_close_range
  if (::syscall(SYS_close_range, 7u, ~0u, 0u) != 0)
#endif
    for (int fd = 7; fd < 4096; ++fd) ::close(fd);
  const int out_fd = 3, err_fd = 4, lifeline = 5, report = 6;

  int exec_pipe[2];
  if (::pipe2(exec_pipe, O_CLOEXEC) != 0) {
    send(report, kExecFailed, errno);
    ::_exit(0);
  }
  const pid_t program = ::fork();
  if (program < 0) {
    send(report, kExecFailed, errno);
    ::_exit(0);
  }
  if (program == 0) {
    ::setpgid(0, 0);
    struct sigaction dfl {};
    dfl.sa_handler = SIG_DFL;
    for (int sig : {SIGINT, SIGTERM, SIGHUP, SIGQUIT, SIGPIPE, SIGXFSZ, SIGCHLD}) ::sigaction(sig, &dfl, nullptr);
    ::sigprocmask(SIG_SETMASK, &none, nullptr);
    const int null_in = ::open("/dev/null", O_RDONLY);
    if (null_in >= 0) ::dup2(null_in, 0);
    ::dup2(out_fd, 1);
    ::dup2(err_fd, 2);
    if (setup.max_file_bytes > 0) {
      const rlimit limit{static_cast<rlim_t>(setup.max_file_bytes), static_cast<rlim_t>(setup.max_file_bytes)};
      ::setrlimit(RLIMIT_FSIZE, &limit);
    }
    int error = 0;
    if (setup.workdir && ::chdir(setup.workdir) != 0) {
      error = errno;
    } else {
      ::execvp(setup.argv[0], setup.argv);
      error = errno;
    }
    ssize_t ignored = ::write(exec_pipe[1], &error, sizeof error);
    (void)ignored;
    ::_exit(127);
  }
  ::setpgid(program, program);  // also from here, so a kill never races the program's own setpgid
  ::close(exec_pipe[1]);
  ::close(out_fd);
  ::close(err_fd);
  int exec_errno = 0;
  ssize_t got;
  do got = ::read(exec_pipe[0], &exec_errno, sizeof exec_errno);
  while (got < 0 && errno == EINTR);
  ::close(exec_pipe[0]);
  if (got == static_cast<ssize_t>(sizeof exec_errno)) {
    int ignored = 0;
    kill_everything(program, ::getpid(), false, &ignored);
    send(report, kExecFailed, exec_errno);
    ::_exit(0);
  }
  send(report, kStarted, program);

  const pid_t self = ::getpid();
  for (;;) {
    // Reap as we go: the program, and orphans that end on their own (no zombies pile up).
    for (;;) {
      int status = 0;
      const pid_t done = ::waitpid(-1, &status, WNOHANG);
      if (done == program) {
        const int leftovers = kill_everything(program, self, true, &status);
        if (leftovers > 0) send(report, kLeftovers, leftovers);
        send(report, kExited, status);
        ::_exit(0);
      }
      if (done <= 0) break;
    }
    pollfd watch{lifeline, POLLIN, 0};
    const timespec second{1, 0};
    if (::ppoll(&watch, 1, &second, &none) > 0) {
      // A byte or end of file: the caller wants the run stopped, or is gone.
      int status = 0;
      kill_everything(program, self, false, &status);
      send(report, kKilled, 0);
      ::_exit(0);
    }
  }
}

bool read_message(int fd, Message* m) {
  char* p = reinterpret_cast<char*>(m);
  size_t have = 0;
  while (have < sizeof *m) {
    const ssize_t got = ::read(fd, p + have, sizeof *m - have);
    if (got > 0) {
      have += static_cast<size_t>(got);
    } else if (got == 0 || errno != EINTR) {
      return false;
    }
  }
  return true;
}

double seconds_since(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

// The caller's descriptors of one run. lifeline: only this process holds its write end; closing
// it (or dying) stops the run. report: the supervisor's messages.
struct RunDescriptors {
  int out_fd = -1, err_fd = -1;
  int lifeline[2] = {-1, -1};
  int report[2] = {-1, -1};
};

// Opens the program's output files and both pipes; on failure closes what it opened and returns
// the message, else "".
std::string open_run_descriptors(const ProcessOptions& options, RunDescriptors& d) {
  d.out_fd = open_output(options.stdout_path);
  d.err_fd = open_output(options.stderr_path);
  if (d.out_fd < 0 || d.err_fd < 0) {
    const std::string bad = d.out_fd < 0 ? options.stdout_path : options.stderr_path;
    if (d.out_fd >= 0) ::close(d.out_fd);
    if (d.err_fd >= 0) ::close(d.err_fd);
    return "cannot open " + bad + " for writing: " + std::strerror(errno);
  }
  if (::pipe2(d.lifeline, O_CLOEXEC) != 0) {
    ::close(d.out_fd);
    ::close(d.err_fd);
    return std::string("pipe: ") + std::strerror(errno);
  }
  if (::pipe2(d.report, O_CLOEXEC) != 0) {
    for (int fd : {d.out_fd, d.err_fd, d.lifeline[0], d.lifeline[1]}) ::close(fd);
    return std::string("pipe: ") + std::strerror(errno);
  }
  return "";
}

// What the caller heard from the supervisor.
struct SupervisorReport {
  pid_t program = 0;
  int leftovers = 0;
  bool cancelled = false;
  bool final_message = false;  // false: the supervisor died or hung without a final word
  Message last{0, 0};
};

// Reads the supervisor's messages until its final one; on timeout or cancel closes the lifeline
// (set to -1 then) and gives the supervisor 30 s to answer.
SupervisorReport await_supervisor(const ProcessOptions& options, int report_fd, int& lifeline_write,
                                  std::chrono::steady_clock::time_point start) {
  SupervisorReport heard;
  bool stop_requested = false;
  double stop_requested_at = 0;
  while (!heard.final_message) {
    if (!stop_requested) {
      heard.cancelled = options.cancel && options.cancel->load();
      const bool timed_out = options.timeout_s > 0 && seconds_since(start) >= options.timeout_s;
      if (heard.cancelled || timed_out) {
        stop_requested = true;
        stop_requested_at = seconds_since(start);
        ::close(lifeline_write);
        lifeline_write = -1;
      }
    } else if (seconds_since(start) - stop_requested_at > 30) {
      break;  // the supervisor does not answer: killed by the caller
    }
    pollfd watch{report_fd, POLLIN, 0};
    const int ready = ::poll(&watch, 1, 10);
    if (ready < 0 && errno != EINTR) break;
    if (ready <= 0) continue;
    if (!read_message(report_fd, &heard.last)) break;  // the supervisor died without a final word
    if (heard.last.kind == kStarted) heard.program = heard.last.value;
    else if (heard.last.kind == kLeftovers) heard.leftovers = heard.last.value;
    else heard.final_message = true;
  }
  return heard;
}

// Fills in the status and message from the supervisor's final word (kExecFailed, kKilled or kExited).
void describe_outcome(const ProcessOptions& options, const SupervisorReport& heard, ProcessResult& result) {
  const Message& m = heard.last;
  if (m.kind == kExecFailed) {
    result.status = ProcessStatus::failed_to_start;
    result.message = "cannot run '" + options.argv[0] + "'" +
                     (!options.working_directory.empty() ? " in " + options.working_directory : std::string()) +
                     ": " + std::strerror(m.value);
    return;
  }
  if (m.kind == kKilled) {
    result.status = heard.cancelled ? ProcessStatus::cancelled : ProcessStatus::timed_out;
    result.message = heard.cancelled ? "killed: campaign cancelled"
                                     : "killed after the " + format_number(options.timeout_s, 6) + " s timeout";
    return;
  }
  const int wait_status = m.value;
  if (WIFEXITED(wait_status)) {
    result.status = ProcessStatus::exited;
    result.exit_code = WEXITSTATUS(wait_status);
    result.message = "exit code " + std::to_string(result.exit_code);
  } else if (WIFSIGNALED(wait_status)) {
    result.status = ProcessStatus::signalled;
    result.signal = WTERMSIG(wait_status);
    result.message = std::string("killed by signal ") + std::to_string(result.signal) + " (" +
                     ::strsignal(result.signal) + ")";
  }
}

}  // namespace

ProcessResult run_process(const ProcessOptions& options) {
  options.Validate();
  ProcessResult result;
  const auto start = std::chrono::steady_clock::now();

  // Everything the supervisor needs is prepared before fork: after it, only async-signal-safe calls.
  std::vector<char*> argv;
  for (const auto& word : options.argv) argv.push_back(const_cast<char*>(word.c_str()));
  argv.push_back(nullptr);
  RunDescriptors d;
  result.message = open_run_descriptors(options, d);
  if (!result.message.empty()) return result;
  const char* workdir = options.working_directory.empty() ? nullptr : options.working_directory.c_str();
  const ChildSetup setup{argv.data(), workdir, d.out_fd, d.err_fd, d.lifeline[0], d.report[1], options.max_file_bytes};

  const pid_t supervisor = ::fork();
  if (supervisor < 0) {
    result.message = std::string("fork: ") + std::strerror(errno);
    for (int fd : {d.out_fd, d.err_fd, d.lifeline[0], d.lifeline[1], d.report[0], d.report[1]}) ::close(fd);
    return result;
  }
  if (supervisor == 0) supervise(setup);
  for (int fd : {d.out_fd, d.err_fd, d.lifeline[0], d.report[1]}) ::close(fd);

  const SupervisorReport heard = await_supervisor(options, d.report[0], d.lifeline[1], start);
  if (d.lifeline[1] >= 0) ::close(d.lifeline[1]);
  ::close(d.report[0]);
  if (!heard.final_message) {
    // Last resort (the supervisor itself was killed or hangs): kill what can still be reached.
    ::kill(supervisor, SIGKILL);
    if (heard.program > 0) ::kill(-heard.program, SIGKILL);
  }
  int supervisor_status = 0;
  while (::waitpid(supervisor, &supervisor_status, 0) < 0 && errno == EINTR) {
  }
  result.wall_time_s = seconds_since(start);
  result.leftover_processes = heard.leftovers;

  if (!heard.final_message) {
    result.status = ProcessStatus::signalled;
    result.signal = WIFSIGNALED(supervisor_status) ? WTERMSIG(supervisor_status) : 0;
    result.message = "the process supervisor ended unexpectedly";
    return result;
  }
  describe_outcome(options, heard, result);
  return result;
}

std::vector<std::string> split_command_line(const std::string& line) {
  std::vector<std::string> words;
  std::string word;
  bool in_word = false;
  char quote = 0;
  for (size_t i = 0; i < line.size(); ++i) {
    const char c = line[i];
    if (quote) {
      if (c == quote) {
        quote = 0;
      } else if (c == '\\' && quote == '"' && i + 1 < line.size()) {
        word += line[++i];
      } else {
        word += c;
      }
    } else if (c == '\'' || c == '"') {
      quote = c;
      in_word = true;
    } else if (c == '\\') {
      if (i + 1 >= line.size())
        throw std::invalid_argument("command template ends with a lone backslash: " + line);
      word += line[++i];
      in_word = true;
    } else if (c == ' ' || c == '\t' || c == '\n') {
      if (in_word) words.push_back(word);
      word.clear();
      in_word = false;
    } else {
      word += c;
      in_word = true;
    }
  }
  if (quote)
    throw std::invalid_argument(std::string("command template has an unterminated ") + quote +
                                " quote: " + line);
  if (in_word) words.push_back(word);
  if (words.empty()) throw std::invalid_argument("command template is empty");
  return words;
}

namespace {

// Walks one word, calling on_text for literal runs and on_name for each placeholder.
template <class Text, class Name>
void scan_placeholders(const std::string& word, Text on_text, Name on_name) {
  for (size_t i = 0; i < word.size(); ++i) {
    const char c = word[i];
    if (c == '{' && i + 1 < word.size() && word[i + 1] == '{') {
      on_text('{');
      ++i;
    } else if (c == '}' && i + 1 < word.size() && word[i + 1] == '}') {
      on_text('}');
      ++i;
    } else if (c == '{') {
      const size_t close = word.find('}', i + 1);
      if (close == std::string::npos)
        throw std::invalid_argument("command template: unterminated '{' in argument '" + word + "'");
      const std::string name = word.substr(i + 1, close - i - 1);
      if (name.empty())
        throw std::invalid_argument("command template: empty placeholder {} in argument '" + word + "'");
      on_name(name);
      i = close;
    } else if (c == '}') {
      throw std::invalid_argument("command template: stray '}' in argument '" + word +
                                  "' (write }} for a literal brace)");
    } else {
      on_text(c);
    }
  }
}

}  // namespace

std::vector<std::string> expand_placeholders(const std::vector<std::string>& words,
                                             const std::map<std::string, std::string>& values) {
  std::vector<std::string> expanded;
  for (const auto& word : words) {
    std::string out;
    scan_placeholders(
        word, [&](char c) { out += c; },
        [&](const std::string& name) {
          const auto it = values.find(name);
          if (it == values.end()) {
            std::string known;
            for (const auto& [key, value] : values) known += (known.empty() ? "" : ", ") + key;
            throw std::invalid_argument("command template: unknown placeholder {" + name +
                                        "} (known: " + known + ")");
          }
          out += it->second;
        });
    expanded.push_back(out);
  }
  return expanded;
}

std::vector<std::string> placeholder_names(const std::vector<std::string>& words) {
  std::vector<std::string> names;
  for (const auto& word : words)
    scan_placeholders(
        word, [](char) {},
        [&](const std::string& name) {
          for (const auto& known : names)
            if (known == name) return;
          names.push_back(name);
        });
  return names;
}

}  // namespace demcal::pipelines
