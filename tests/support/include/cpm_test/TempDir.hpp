#pragma once
// A fresh folder under /tmp for one test, removed with everything in it at the end.
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>

namespace cpm_test {

struct TempDir
{
    std::filesystem::path path;
    TempDir()
    {
        char tmpl[] = "/tmp/cpm_test.XXXXXX";
        path = ::mkdtemp(tmpl);
    }
    ~TempDir() { std::filesystem::remove_all(path); }
    TempDir(const TempDir&) = delete;
    TempDir& operator=(const TempDir&) = delete;
    /// The path of `name` in the folder (not made).
    std::string file(const std::string& name) const { return (path / name).string(); }
    /// Writes `text` to `name` in the folder; its path.
    std::string write(const std::string& name, const std::string& text) const
    {
        std::ofstream(path / name) << text;
        return file(name);
    }
    /// The text of `name` in the folder; "" while it does not exist.
    std::string read(const std::string& name) const
    {
        std::ifstream in(path / name);
        return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
    }
};

/// A real disk of `size` (a tmpfs, e.g. "256k") mounted at `at` (made) for a test that fills
/// it; unmounted at the end. Mounting needs root: check mounted().
struct SmallDisk
{
    std::string at;
    bool mounted_ = false;
    SmallDisk(const std::string& where, const std::string& size) : at(where)
    {
        std::filesystem::create_directories(at);
        mounted_ = std::system(("mount -t tmpfs -o size=" + size + " tmpfs " + at).c_str()) == 0;
    }
    ~SmallDisk()
    {
        if (mounted_) (void)std::system(("umount " + at).c_str());
    }
    SmallDisk(const SmallDisk&) = delete;
    SmallDisk& operator=(const SmallDisk&) = delete;
    bool mounted() const { return mounted_; }
};

}  // namespace cpm_test
