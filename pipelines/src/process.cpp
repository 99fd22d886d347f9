#include "demcal/pipelines/process.hpp"

#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstring>
#include <stdexcept>
#include <thread>

namespace demcal::pipelines {

void ProcessOptions::Validate() const {
  if (argv.empty() || argv[0].empty())
    throw std::invalid_argument("process: empty command (no program to run)");
  if (!(timeout_s >= 0))
    throw std::invalid_argument("process: timeout_s must be >= 0, got " + std::to_string(timeout_s));
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

void kill_group(pid_t pid) {
  ::kill(-pid, SIGKILL);
  ::kill(pid, SIGKILL);
}

}  // namespace

ProcessResult run_process(const ProcessOptions& options) {
  options.Validate();
  ProcessResult result;
  const auto start = std::chrono::steady_clock::now();
  auto elapsed = [&] {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  };

  // Everything the child needs is prepared before fork: after it, only async-signal-safe calls.
  std::vector<char*> argv;
  for (const auto& word : options.argv) argv.push_back(const_cast<char*>(word.c_str()));
  argv.push_back(nullptr);
  const int out_fd = open_output(options.stdout_path);
  const int err_fd = open_output(options.stderr_path);
  if (out_fd < 0 || err_fd < 0) {
    const std::string bad = out_fd < 0 ? options.stdout_path : options.stderr_path;
    if (out_fd >= 0) ::close(out_fd);
    if (err_fd >= 0) ::close(err_fd);
    result.message = "cannot open " + bad + " for writing: " + std::strerror(errno);
    return result;
  }
  // A pipe with close-on-exec tells the parent whether exec succeeded (it carries errno if not).
  int status_pipe[2];
  if (::pipe2(status_pipe, O_CLOEXEC) != 0) {
    ::close(out_fd);
    ::close(err_fd);
    result.message = std::string("pipe: ") + std::strerror(errno);
    return result;
  }
  const char* workdir = options.working_directory.empty() ? nullptr : options.working_directory.c_str();

  const pid_t pid = ::fork();
  if (pid < 0) {
    result.message = std::string("fork: ") + std::strerror(errno);
    ::close(out_fd);
    ::close(err_fd);
    ::close(status_pipe[0]);
    ::close(status_pipe[1]);
    return result;
  }
  if (pid == 0) {
    ::setpgid(0, 0);
    const int null_in = ::open("/dev/null", O_RDONLY);
    if (null_in >= 0) ::dup2(null_in, 0);
    ::dup2(out_fd, 1);
    ::dup2(err_fd, 2);
    int error = 0;
    if (workdir && ::chdir(workdir) != 0) {
      error = errno;
    } else {
      ::execvp(argv[0], argv.data());
      error = errno;
    }
    ssize_t ignored = ::write(status_pipe[1], &error, sizeof error);
    (void)ignored;
    ::_exit(127);
  }
  ::setpgid(pid, pid);  // also from the parent, so a kill never races the child's own setpgid
  ::close(out_fd);
  ::close(err_fd);
  ::close(status_pipe[1]);
  int child_errno = 0;
  const ssize_t got = ::read(status_pipe[0], &child_errno, sizeof child_errno);
  ::close(status_pipe[0]);
  if (got == static_cast<ssize_t>(sizeof child_errno)) {
    int ignored_status = 0;
    ::waitpid(pid, &ignored_status, 0);
    result.status = ProcessStatus::failed_to_start;
    result.wall_time_s = elapsed();
    result.message = "cannot run '" + options.argv[0] + "'" +
                     (workdir ? " in " + options.working_directory : std::string()) + ": " +
                     std::strerror(child_errno);
    return result;
  }

  int wait_status = 0;
  auto poll_interval = std::chrono::microseconds(200);
  while (true) {
    const pid_t done = ::waitpid(pid, &wait_status, WNOHANG);
    if (done == pid) break;
    if (done < 0 && errno != EINTR) {
      result.message = std::string("waitpid: ") + std::strerror(errno);
      kill_group(pid);
      return result;
    }
    const bool cancelled = options.cancel && options.cancel->load();
    const bool timed_out = options.timeout_s > 0 && elapsed() >= options.timeout_s;
    if (cancelled || timed_out) {
      kill_group(pid);
      ::waitpid(pid, &wait_status, 0);
      result.wall_time_s = elapsed();
      result.status = cancelled ? ProcessStatus::cancelled : ProcessStatus::timed_out;
      char buffer[96];
      std::snprintf(buffer, sizeof buffer, "killed after the %g s timeout", options.timeout_s);
      result.message = cancelled ? "killed: campaign cancelled" : buffer;
      return result;
    }
    std::this_thread::sleep_for(poll_interval);
    poll_interval = std::min(poll_interval * 2, std::chrono::microseconds(20000));
  }
  result.wall_time_s = elapsed();
  // Whatever the program left running in its group goes with it.
  ::kill(-pid, SIGKILL);
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
