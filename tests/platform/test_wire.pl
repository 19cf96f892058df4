/*  plunit tests of wire.pl's frames, byte by byte, on memory files.
    Run: swipl -g run_tests -t halt test_wire.pl
*/
:- use_module('../../platform_pl/wire').
:- use_module(library(plunit)).
:- use_module(library(memfile)).

:- begin_tests(wire).

%   The bytes frame_write/3 puts on a stream.
frame_bytes(Kind, Term, Bytes) :-
    setup_call_cleanup(
        new_memory_file(MF),
        ( setup_call_cleanup(open_memory_file(MF, write, Out, [encoding(octet)]),
                             frame_write(Out, Kind, Term),
                             close(Out)),
          memory_file_to_codes(MF, Bytes, octet)
        ),
        free_memory_file(MF)).

%   Read one frame back from Bytes.
bytes_frame(Bytes, Frame) :-
    setup_call_cleanup(
        new_memory_file(MF),
        ( setup_call_cleanup(open_memory_file(MF, write, Out, [encoding(octet)]),
                             forall(member(B, Bytes), put_byte(Out, B)),
                             close(Out)),
          setup_call_cleanup(open_memory_file(MF, read, In, [encoding(octet)]),
                             frame_read(In, Frame, [binary(true), max_size(10000000)]),
                             close(In))
        ),
        free_memory_file(MF)).

be32(N, [B0, B1, B2, B3]) :-
    B0 is (N >> 24) /\ 0xff, B1 is (N >> 16) /\ 0xff,
    B2 is (N >> 8) /\ 0xff, B3 is N /\ 0xff.

%   A text frame: the 12-byte header (magic, version 1, kind T, two zero
%   bytes, the body's length in bytes, big-endian) and a body that is
%   the UTF-8 of the canonical text. The term has letters of two and
%   four bytes in UTF-8 and is longer than 255 bytes, so a length
%   counted in characters, or written in one byte, fails (control: the
%   character count differs from the byte count).
test(text_frame_bytes) :-
    length(L, 60), maplist(=('é∑😀'), L),
    Term = msg(L, "naïve", 'a b'),
    frame_bytes(text, Term, Bytes),
    Bytes = [0'D, 0'F, 0'R, 0'L, 1, 0'T, 0, 0, L0, L1, L2, L3 | Body],
    format(string(Text), "~k .~n", [Term]),
    string_length(Text, Chars),
    string_codes(Text, TextCodes),
    phrase(utf8_bytes(TextCodes), Expected),
    assertion(Body == Expected),
    length(Body, Len),
    assertion(Len > 255),
    assertion(Len =\= Chars),
    be32(Len, [L0, L1, L2, L3]),
    bytes_frame(Bytes, Frame),
    assertion(Frame =@= frame(text, Term)).

%   A binary frame: kind B, the length of the fast serialisation, and a
%   body that decodes to the term.
test(binary_frame_bytes) :-
    numlist(1, 1000, Is),
    findall(F, ( member(I, Is), F is I * 0.25 ), Fs),
    Term = transfer(m1, move, f(X, X, _), Fs),
    frame_bytes(binary, Term, Bytes),
    Bytes = [0'D, 0'F, 0'R, 0'L, 1, 0'B, 0, 0, L0, L1, L2, L3 | Body],
    fast_term_serialized(Term, String),
    string_length(String, Len),
    length(Body, Len),
    be32(Len, [L0, L1, L2, L3]),
    bytes_frame(Bytes, Frame),
    assertion(Frame =@= frame(binary, Term)).

%   text_term_bytes/2 both ways, non-ASCII included.
test(text_term_bytes_round_trip) :-
    Term = f('é', "∑😀", [1.5, -2], 'it''s'),
    text_term_bytes(Term, Bytes),
    assertion(forall(member(B, Bytes), between(0, 255, B))),
    text_term_bytes(Back, Bytes),
    assertion(Back == Term).

%   UTF-8 of a list of code points, written out here (not taken from the
%   code under test).
utf8_bytes([]) --> [].
utf8_bytes([C|Cs]) --> utf8_char(C), utf8_bytes(Cs).

utf8_char(C) --> { C < 0x80 }, !, [C].
utf8_char(C) --> { C < 0x800 }, !,
    { B0 is 0xC0 \/ (C >> 6), B1 is 0x80 \/ (C /\ 0x3F) }, [B0, B1].
utf8_char(C) --> { C < 0x10000 }, !,
    { B0 is 0xE0 \/ (C >> 12), B1 is 0x80 \/ ((C >> 6) /\ 0x3F),
      B2 is 0x80 \/ (C /\ 0x3F) }, [B0, B1, B2].
utf8_char(C) -->
    { B0 is 0xF0 \/ (C >> 18), B1 is 0x80 \/ ((C >> 12) /\ 0x3F),
      B2 is 0x80 \/ ((C >> 6) /\ 0x3F), B3 is 0x80 \/ (C /\ 0x3F) },
    [B0, B1, B2, B3].

:- end_tests(wire).
