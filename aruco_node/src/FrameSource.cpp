#include "FrameSource.hpp"

#include <cpm/Error.hpp>
#include <cpm/aruco/Images.hpp>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <thread>

namespace cpm::aruco {
namespace {

cv::Mat to_grey(const cv::Mat& image)
{
    if (image.channels() == 1) return image;
    cv::Mat grey;
    cv::cvtColor(image, grey, image.channels() == 4 ? cv::COLOR_BGRA2GRAY : cv::COLOR_BGR2GRAY);
    return grey;
}

/// Paces a replay: next() returns no earlier than one period after the previous one.
class Pace
{
public:
    explicit Pace(double fps) : period_(std::chrono::nanoseconds(int64_t(1e9 / std::max(fps, 0.1)))) {}
    void wait()
    {
        auto now = std::chrono::steady_clock::now();
        if (due_.time_since_epoch().count() == 0) due_ = now;
        if (due_ > now) std::this_thread::sleep_until(due_);
        due_ = std::max(due_, now) + period_;
    }

private:
    std::chrono::nanoseconds period_;
    std::chrono::steady_clock::time_point due_{};
};

class Capture : public FrameSource
{
public:
    Capture(const std::string& path, bool device) : path_(path), device_(device)
    {
        if (!std::filesystem::exists(path)) throw Error(path + ": no such " + std::string(device ? "device" : "video file"));
        if (device) {
            capture_.open(path, cv::CAP_V4L2);
        } else {
            capture_.open(path);
        }
        if (!capture_.isOpened()) {
            throw Error(path + ": cannot open the " + std::string(device ? "camera device (is it a V4L2 capture device?)" : "video file"));
        }
        // A video is replayed at its own rate (unknown: as fast as it decodes); a device paces itself.
        const double fps = capture_.get(cv::CAP_PROP_FPS);
        if (!device) pace_ = Pace(fps > 0 ? fps : 1000);
    }
    cv::Mat next() override
    {
        cv::Mat frame;
        if (!device_) pace_.wait();
        if (!capture_.read(frame)) return {};
        return to_grey(frame);
    }
    std::string current() const override { return path_; }

private:
    std::string path_;
    bool device_;
    cv::VideoCapture capture_;
    Pace pace_{30};
};

class Images : public FrameSource
{
public:
    Images(const std::string& folder, double fps) : folder_(folder), pace_(fps), files_(list_images(folder)) {}
    cv::Mat next() override
    {
        while (index_ < files_.size()) {
            pace_.wait();
            cv::Mat image = cv::imread(files_[index_++], cv::IMREAD_GRAYSCALE);
            if (!image.empty()) return image;
            return cv::Mat(1, 1, CV_8UC3);  // unreadable: a frame the node counts as bad
        }
        return {};
    }
    std::string current() const override { return index_ ? files_[index_ - 1] : folder_; }

private:
    std::string folder_;
    Pace pace_;
    std::vector<std::string> files_;
    size_t index_ = 0;
};

}  // namespace

std::unique_ptr<FrameSource> open_device(const std::string& path) { return std::make_unique<Capture>(path, true); }
std::unique_ptr<FrameSource> open_video(const std::string& path) { return std::make_unique<Capture>(path, false); }
std::unique_ptr<FrameSource> open_images(const std::string& folder, double fps) { return std::make_unique<Images>(folder, fps); }

}  // namespace cpm::aruco
