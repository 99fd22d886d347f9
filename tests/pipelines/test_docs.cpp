// The user pages of the commands (docs/commands/*.md) against the program: for every command path
// (`demcal`, `demcal calibrate`, `demcal scene arch`, ...) the real `demcal PATH --help` is run and
// the long flags it prints are compared with the rows of the page's options tables.
//
// The rules (docs/commands/README.md; scripts/check-options-tables.py applies the same ones):
// - the page of `demcal NAME ...` is docs/commands/NAME.md, that of `demcal` docs/commands/README.md;
// - its options tables are the tables under a heading that contains "options" and the code span
//   `demcal PATH` (one heading may name several paths: a table shared by `scene arch` and `scene wall`);
// - a row's first cell is one code span holding the option's names as --help prints them
//   (`--max-simulations`, `-o,--output`, `--swarm,--population`);
// - the rows name every long flag the help prints and no other; `--help` and the program's own
//   options (those `demcal --help` prints, such as `--limit`) are documented once, on README.md;
// - a page has at most 400 lines.
// Besides, every link between the project's Markdown pages (README.md, docs/) reaches its file,
// and a link to a heading reaches one of that page's headings.
#include <gtest/gtest.h>

#include <algorithm>
#include <cctype>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <regex>
#include <set>
#include <sstream>
#include <string>
#include <vector>

namespace fs = std::filesystem;

namespace {

using CommandPath = std::vector<std::string>;

const fs::path kPages = fs::path(DEMCAL_SOURCE_DIR) / "docs" / "commands";
constexpr int kMaxPageLines = 400;

std::string joined(const CommandPath& path) {
  std::string text = "demcal";
  for (const auto& word : path) text += " " + word;
  return text;
}

// stdout and stderr of `demcal PATH --help`; the exit status must be 0.
std::string help_text(const CommandPath& path) {
  const std::string command = std::string(DEMCAL_BINARY) + " " + joined(path).substr(6) + " --help 2>&1";
  FILE* pipe = popen(command.c_str(), "r");
  if (pipe == nullptr) {
    ADD_FAILURE() << "cannot run " << command;
    return "";
  }
  std::string text;
  char buffer[4096];
  while (std::fgets(buffer, sizeof buffer, pipe) != nullptr) text += buffer;
  EXPECT_EQ(pclose(pipe), 0) << command << "\n" << text;
  return text;
}

std::vector<std::string> lines_of(const std::string& text) {
  std::vector<std::string> lines;
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);) lines.push_back(line);
  return lines;
}

std::set<std::string> long_flags(const std::string& names) {
  static const std::regex flag("--[a-z0-9][a-z0-9-]*");
  std::set<std::string> flags;
  for (std::sregex_iterator it(names.begin(), names.end(), flag), end; it != end; ++it) flags.insert(it->str());
  return flags;
}

struct Help {
  std::vector<std::string> names;        // as printed, e.g. "-o,--output", "--beam-rotation,--no-beam-rotation"
  std::vector<std::string> subcommands;
};

// CLI11's layout: section titles at column 0 ("Options:", "Subcommands:", a group such as
// "Effects (0 = off):"), an option line starts with two spaces and a dash, its name up to the first
// space (a flag's default such as "{false}" stripped), descriptions that wrap start further right.
Help parse_help(const std::string& text) {
  static const std::regex option_line("^  (-\\S+).*");
  static const std::regex subcommand_line("^  ([a-z][a-z0-9-]*)(\\s.*)?");
  static const std::regex trailing_default("\\{[^}]*\\}$");
  Help help;
  std::string section;
  for (const auto& line : lines_of(text)) {
    std::smatch m;
    if (!line.empty() && line[0] != ' ') {
      section = line.substr(0, line.find(':'));
    } else if (std::regex_match(line, m, option_line)) {
      help.names.push_back(std::regex_replace(m[1].str(), trailing_default, ""));
    } else if (section == "Subcommands" && std::regex_match(line, m, subcommand_line)) {
      help.subcommands.push_back(m[1].str());
    }
  }
  return help;
}

struct Page {
  int lines = 0;
  std::map<CommandPath, std::vector<std::string>> rows;  // first cells of the options tables' rows
};

std::string lower(std::string text) {
  for (auto& c : text) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return text;
}

// A line that opens or closes a code fence (```): what lies between is code, not Markdown.
bool fence_line(const std::string& line) { return line.rfind("```", 0) == 0; }

Page read_page(const fs::path& file) {
  static const std::regex heading("^#{1,6} .*");
  static const std::regex command_span("`demcal((?: [a-z][a-z0-9-]*)*)`");
  static const std::regex separator("^\\|[\\s:|-]+\\|\\s*$");
  std::ifstream in(file);
  std::stringstream buffer;
  buffer << in.rdbuf();
  const auto lines = lines_of(buffer.str());
  Page page;
  page.lines = static_cast<int>(lines.size());
  std::vector<CommandPath> current;
  bool fence = false;
  for (std::size_t i = 0; i < lines.size(); ++i) {
    const std::string& line = lines[i];
    if (fence_line(line)) fence = !fence;
    if (fence || fence_line(line)) continue;
    if (std::regex_match(line, heading)) {
      current.clear();
      if (lower(line).find("options") == std::string::npos) continue;
      for (std::sregex_iterator it(line.begin(), line.end(), command_span), end; it != end; ++it) {
        std::istringstream words((*it)[1].str());
        CommandPath path;
        for (std::string word; words >> word;) path.push_back(word);
        current.push_back(path);
        page.rows[path];
      }
      continue;
    }
    if (current.empty() || line.rfind('|', 0) != 0 || std::regex_match(line, separator)) continue;
    if (i + 1 < lines.size() && std::regex_match(lines[i + 1], separator)) continue;  // a header row
    std::string cell = line.substr(1, line.find('|', 1) - 1);
    cell.erase(0, cell.find_first_not_of(' '));
    cell.erase(cell.find_last_not_of(' ') + 1);
    for (const auto& path : current) page.rows[path].push_back(cell);
  }
  return page;
}

// Every command path the program has: `demcal`, each subcommand and each of theirs.
std::vector<CommandPath> command_paths() {
  std::vector<CommandPath> paths{{}};
  for (const auto& name : parse_help(help_text({})).subcommands) {
    paths.push_back({name});
    for (const auto& sub : parse_help(help_text({name})).subcommands) paths.push_back({name, sub});
  }
  return paths;
}

fs::path page_of(const CommandPath& path) { return kPages / (path.empty() ? "README.md" : path[0] + ".md"); }

// GitHub's anchor of a heading: lower case, spaces to hyphens, every character but letters, digits,
// hyphens and underscores left out. Non-ASCII letters are kept (Latin and Greek; `ç`), other
// non-ASCII characters (dashes, arrows, ×) left out; upper-case non-ASCII letters are not lowered.
std::string heading_anchor(const std::string& heading) {
  std::string anchor;
  for (std::size_t i = 0; i < heading.size();) {
    const auto c = static_cast<unsigned char>(heading[i]);
    if (c < 0x80) {
      if (std::isalnum(c) || c == '-' || c == '_') anchor += static_cast<char>(std::tolower(c));
      if (c == ' ') anchor += '-';
      ++i;
      continue;
    }
    const std::size_t length = c >= 0xF0 ? 4 : c >= 0xE0 ? 3 : 2;
    unsigned code = length == 2 ? c & 0x1F : length == 3 ? c & 0x0F : c & 0x07;
    for (std::size_t k = 1; k < length && i + k < heading.size(); ++k)
      code = (code << 6) | (static_cast<unsigned char>(heading[i + k]) & 0x3F);
    const bool letter = (code >= 0xC0 && code <= 0x24F && code != 0xD7 && code != 0xF7) || (code >= 0x370 && code <= 0x3FF);
    if (letter) anchor += heading.substr(i, length);
    i += length;
  }
  return anchor;
}

// The anchors of a Markdown page's headings (outside code fences); a repeated heading's later
// anchors get -1, -2, ... as GitHub numbers them.
std::set<std::string> heading_anchors(const fs::path& file) {
  std::ifstream in(file);
  std::set<std::string> anchors;
  std::map<std::string, int> seen;
  bool fence = false;
  for (std::string line; std::getline(in, line);) {
    if (fence_line(line)) fence = !fence;
    if (fence || line.rfind('#', 0) != 0) continue;
    const std::size_t text = line.find_first_not_of('#');
    if (text == std::string::npos || line[text] != ' ') continue;
    std::string anchor = heading_anchor(line.substr(text + 1));
    const int repeat = seen[anchor]++;
    anchors.insert(repeat == 0 ? anchor : anchor + "-" + std::to_string(repeat));
  }
  return anchors;
}

}  // namespace

TEST(Docs, HelpListsTheCommandsAndTheirOptions) {
  const auto paths = command_paths();
  ASSERT_GE(paths.size(), 11u) << "demcal --help lists fewer commands than expected";
  const Help root = parse_help(help_text({}));
  EXPECT_NE(std::find(root.names.begin(), root.names.end(), "--limit"), root.names.end());
  const Help diagnose = parse_help(help_text({"diagnose"}));
  EXPECT_NE(std::find(diagnose.names.begin(), diagnose.names.end(), "--max-simulations"), diagnose.names.end());
  const Help wall = parse_help(help_text({"scene", "wall"}));
  EXPECT_NE(std::find(wall.names.begin(), wall.names.end(), "--beam-rotation,--no-beam-rotation"), wall.names.end());
  EXPECT_NE(std::find(wall.names.begin(), wall.names.end(), "-o,--output"), wall.names.end());
  EXPECT_NE(std::find(wall.names.begin(), wall.names.end(), "--beam-kr"), wall.names.end());  // in the "Effects" group
}

TEST(Docs, EveryCommandsOptionsTableMatchesItsHelp) {
  std::set<std::string> global_flags;
  for (const auto& name : parse_help(help_text({})).names)
    for (const auto& flag : long_flags(name)) global_flags.insert(flag);
  static const std::regex row_cell("`(-[^`\\s]+)`");
  const auto paths = command_paths();
  std::map<fs::path, Page> pages;
  for (const auto& path : paths) {
    const fs::path file = page_of(path);
    const std::string label = joined(path);
    if (!fs::exists(file)) {
      ADD_FAILURE() << file << ": missing, the page of `" << label << "`";
      continue;
    }
    if (!pages.count(file)) pages[file] = read_page(file);
    const Page& page = pages[file];
    // --help and the program's own options are documented once, on README.md
    std::set<std::string> skip;
    if (!path.empty()) {
      skip = global_flags;
      skip.insert("--help");
    }
    std::set<std::string> printed;  // long flags of the help, less those documented elsewhere
    for (const auto& name : parse_help(help_text(path)).names)
      for (const auto& flag : long_flags(name))
        if (!skip.count(flag)) printed.insert(flag);
    std::set<std::string> documented;
    std::vector<std::string> names;
    const auto rows = page.rows.count(path) ? page.rows.at(path) : std::vector<std::string>{};
    for (const auto& cell : rows) {
      std::smatch m;
      if (!std::regex_match(cell, m, row_cell)) {
        ADD_FAILURE() << file << ": `" << label << "`: row '" << cell << "' is not one code span naming an option";
        continue;
      }
      names.push_back(m[1].str());
      for (const auto& flag : long_flags(m[1].str())) {
        EXPECT_TRUE(documented.insert(flag).second) << file << ": `" << label << "`: " << flag << " has two rows";
      }
    }
    for (const auto& flag : printed)
      EXPECT_TRUE(documented.count(flag)) << file << ": `" << label << "`: no row for " << flag << ", which --help prints";
    for (const auto& flag : documented)
      EXPECT_TRUE(printed.count(flag)) << file << ": `" << label << "`: row " << flag << " is not an option --help prints"
                                       << (skip.count(flag) ? " here (documented once, on README.md)" : "");
    // the names as --help prints them, aliases included
    for (const auto& name : parse_help(help_text(path)).names) {
      const auto flags = long_flags(name);
      bool skipped = false;
      for (const auto& flag : flags) skipped = skipped || skip.count(flag);
      if (skipped || flags.empty()) continue;
      if (documented.count(*flags.begin())) {
        EXPECT_NE(std::find(names.begin(), names.end(), name), names.end())
            << file << ": `" << label << "`: the row of " << *flags.begin() << " should read `" << name << "` as --help prints it";
      }
    }
  }
  // no table for a command that does not exist; no page over the length limit
  for (const auto& [file, page] : pages) {
    EXPECT_LE(page.lines, kMaxPageLines) << file;
    for (const auto& [path, rows] : page.rows)
      EXPECT_NE(std::find(paths.begin(), paths.end(), path), paths.end())
          << file << ": an options heading names `" << joined(path) << "`, which is no command";
  }
}

// Links between the pages: `[text](path)`, `[text](path#anchor)` and `[text](#anchor)`, outside
// code fences; addresses with a scheme (https:, mailto:) are not followed.
TEST(Docs, EveryLinkBetweenPagesReachesItsFileAndHeading) {
  const fs::path root(DEMCAL_SOURCE_DIR);
  std::vector<fs::path> pages{root / "README.md"};
  for (const auto& entry : fs::recursive_directory_iterator(root / "docs"))
    if (entry.path().extension() == ".md") pages.push_back(entry.path());
  static const std::regex link("\\]\\(([^()\\s]+)\\)");
  std::map<fs::path, std::set<std::string>> anchors;
  int links = 0;
  for (const auto& page : pages) {
    std::ifstream in(page);
    bool fence = false;
    int number = 0;
    for (std::string line; std::getline(in, line);) {
      ++number;
      if (fence_line(line)) fence = !fence;
      if (fence) continue;
      for (std::sregex_iterator it(line.begin(), line.end(), link), end; it != end; ++it) {
        const std::string target = (*it)[1].str();
        if (target.find(':') != std::string::npos) continue;
        ++links;
        const std::size_t hash = target.find('#');
        const std::string file_part = target.substr(0, hash);
        const fs::path file = file_part.empty() ? page : (page.parent_path() / file_part).lexically_normal();
        const std::string where = page.lexically_relative(root).string() + ":" + std::to_string(number) + ": " + target;
        if (!fs::exists(file)) {
          ADD_FAILURE() << where << ": no such file";
          continue;
        }
        if (hash == std::string::npos || file.extension() != ".md") continue;
        if (!anchors.count(file)) anchors[file] = heading_anchors(file);
        EXPECT_TRUE(anchors[file].count(target.substr(hash + 1))) << where << ": no such heading";
      }
    }
  }
  EXPECT_GT(links, 100);  // the pages link to each other
}
