#include <cpm/read_text_file.hpp>

#include <cpm/Error.hpp>

#include <cerrno>
#include <cstring>
#include <fstream>
#include <sstream>
#include <sys/stat.h>

namespace cpm {

std::string read_text_file(const std::string& path, const std::string& what)
{
    struct stat st{};
    if (::stat(path.c_str(), &st) == 0 && S_ISDIR(st.st_mode)) {
        throw Error(path + ": cannot read it as the " + what + ": it is a directory");
    }
    std::ifstream in(path);
    if (!in) {
        const int e = errno;
        std::string why = e == ENOENT ? "no such file" : e == EACCES ? "permission denied" : std::strerror(e);
        throw Error(path + ": cannot open the " + what + ": " + why);
    }
    std::stringstream text;
    text << in.rdbuf();
    return text.str();
}

}  // namespace cpm
