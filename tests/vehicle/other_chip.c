/* A program for another AVR (an ATmega328P): firmware_hil must refuse it by name. */
int main(void)
{
    for (;;) {
    }
}
