// softcath scale: reference firmware for an Arduino-class board with an HX711 load-cell amplifier
// (library "HX711" by Bogdan Necula). Speaks the line protocol of docs/lab.md at 115200 baud:
//   host -> board:  "TARE\n"         zero the reading at the present load
//   board -> host:  "F <newtons>\n"  the force along the cell's axis, every reading (80 Hz mode; >= 20 Hz)
//                   "ERR <text>\n"   a fault (the HX711 does not answer, unknown command)
// Not compiled in CI: build it with the Arduino IDE or arduino-cli; calibrate NEWTONS_PER_COUNT
// with a known weight (a 100 g mass is 0.981 N).
#include "HX711.h"

const int DOUT_PIN = 3, SCK_PIN = 2;
const float NEWTONS_PER_COUNT = 2.2e-6;   // your cell and gain: measure it
HX711 cell;
char line[81];
int lineLength = 0;

void setup() {
  Serial.begin(115200);
  cell.begin(DOUT_PIN, SCK_PIN);
  cell.set_scale(1.0 / NEWTONS_PER_COUNT);
  cell.tare();
}

void loop() {
  while (Serial.available()) {
    char c = Serial.read();
    if (c == '\n' || c == '\r') {
      line[lineLength] = 0;
      if (lineLength > 0) {
        if (strcmp(line, "TARE") == 0) cell.tare(10);
        else { Serial.print("ERR unknown command: "); Serial.println(line); }
      }
      lineLength = 0;
    } else if (lineLength < 80) {
      line[lineLength++] = c;
    } else {
      lineLength = 0;
    }
  }
  if (cell.wait_ready_timeout(200)) {
    Serial.print("F ");
    Serial.println(cell.get_units(1), 5);
  } else {
    Serial.println("ERR HX711 not ready (wiring?)");
  }
}
