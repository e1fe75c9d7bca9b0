// softcath regulator: reference firmware for an Arduino-class board (one pressure sensor and one
// proportional valve per channel). Speaks the line protocol of docs/lab.md at 115200 baud:
//   host -> board:  "SET <ch> <Pa>\n"  gauge setpoint of channel ch;  "VENT\n"  all channels to zero
//   board -> host:  "P <ch> <Pa>\n"    gauge reading, every 20 ms per channel (50 Hz)
//                   "ERR <text>\n"     a fault (unknown command, sensor out of its range)
// Safety on the board itself: setpoints are clamped to MAX_PA, and it vents when no SET/VENT came
// for 1 s (the host re-sends every 0.1 s). Not compiled in CI: build it with the Arduino IDE or
// arduino-cli for your board and check the pins and sensor scaling below against your wiring.

const int N_CHANNELS = 2;
const int SENSOR_PIN[N_CHANNELS] = {A0, A1};   // analogue pressure sensors (ratiometric 0.5-4.5 V)
const int VALVE_PIN[N_CHANNELS] = {9, 10};     // PWM into the proportional valves' drivers
const float SENSOR_FULL_SCALE_PA = 100000.0;   // the sensor's range: 0..1 bar gauge over 0.5-4.5 V
const float MAX_PA = 30000.0;                  // never command above this (the design's max_pressure)
const float GAIN = 0.004;                      // PI controller, PWM counts per Pa and per Pa*s
const float INTEGRAL_GAIN = 0.02;
const unsigned long REPORT_MS = 20;
const unsigned long WATCHDOG_MS = 1000;

float setpoint[N_CHANNELS];
float integral[N_CHANNELS];
unsigned long lastCommand = 0, lastReport = 0, lastControl = 0;
char line[81];
int lineLength = 0;

float readPascal(int ch) {
  float volts = analogRead(SENSOR_PIN[ch]) * 5.0 / 1023.0;
  return (volts - 0.5) / 4.0 * SENSOR_FULL_SCALE_PA;
}

void vent() {
  for (int ch = 0; ch < N_CHANNELS; ch++) {
    setpoint[ch] = 0;
    integral[ch] = 0;
    analogWrite(VALVE_PIN[ch], 0);
  }
}

void handleLine(char *text) {
  int ch;
  long pa;
  if (strcmp(text, "VENT") == 0) {
    vent();
    lastCommand = millis();
  } else if (sscanf(text, "SET %d %ld", &ch, &pa) == 2 && ch >= 0 && ch < N_CHANNELS) {
    setpoint[ch] = constrain((float)pa, 0.0, MAX_PA);
    lastCommand = millis();
  } else {
    Serial.print("ERR unknown command: ");
    Serial.println(text);
  }
}

void setup() {
  Serial.begin(115200);
  for (int ch = 0; ch < N_CHANNELS; ch++) pinMode(VALVE_PIN[ch], OUTPUT);
  vent();
}

void loop() {
  while (Serial.available()) {
    char c = Serial.read();
    if (c == '\n' || c == '\r') {
      line[lineLength] = 0;
      if (lineLength > 0) handleLine(line);
      lineLength = 0;
    } else if (lineLength < 80) {
      line[lineLength++] = c;
    } else {
      lineLength = 0;   // an overlong line is dropped
      Serial.println("ERR line too long");
    }
  }
  unsigned long now = millis();
  if (now - lastCommand > WATCHDOG_MS) vent();
  if (now - lastControl >= 5) {                // the PI loop at 200 Hz
    float dt = (now - lastControl) * 1e-3;
    lastControl = now;
    for (int ch = 0; ch < N_CHANNELS; ch++) {
      if (setpoint[ch] <= 0) { analogWrite(VALVE_PIN[ch], 0); continue; }
      float error = setpoint[ch] - readPascal(ch);
      integral[ch] = constrain(integral[ch] + error * dt, -5000.0, 5000.0);
      analogWrite(VALVE_PIN[ch], (int)constrain(GAIN * error + INTEGRAL_GAIN * integral[ch], 0.0, 255.0));
    }
  }
  if (now - lastReport >= REPORT_MS) {
    lastReport = now;
    for (int ch = 0; ch < N_CHANNELS; ch++) {
      float pa = readPascal(ch);
      if (pa < -0.1 * SENSOR_FULL_SCALE_PA || pa > 1.1 * SENSOR_FULL_SCALE_PA) {
        Serial.print("ERR sensor ");
        Serial.print(ch);
        Serial.println(" outside its range (wiring?)");
        continue;
      }
      Serial.print("P ");
      Serial.print(ch);
      Serial.print(' ');
      Serial.println((long)pa);
    }
  }
}
