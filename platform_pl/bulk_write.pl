:- module(bulk_write,
          [ write_bytes/2,              % +Stream, +Bytes
            bulk_write_native/1         % -Boolean
          ]).

/** <module> Writing a large byte string to a binary stream in one piece

SWI-Prolog 9.0.4 moves every byte of a string written with write/2 (or
format/3, or C's Sfwrite()) through its per-byte output path: about 8 ns
a byte, so 8 ms for the 1 MB frame of an agent carrying 100,000 floats,
a quarter of that hop. write_bytes/2 hands the bytes to the stream's own
write function at once instead (the kernel's send, or SSL_write, which
then fills whole 16 KB TLS records): about 2 ms for the same megabyte.

The work is done by a foreign predicate, native/bulk_write.c, which
`scripts/setup.sh` compiles with swipl-ld (`platform_pl/native/build.sh`
does only that). Where the library is not built, or the stream is not
binary, write_bytes/2 is write/2: the same bytes, slower.
bulk_write_native/1 says which is in use (`dfrl bench migrate` reports
it).
*/

:- use_module(native_library, [native_library_load/2]).
:- dynamic native/1.

:- initialization(( native_library_load(bulk_write, Loaded),
                    assertz(native(Loaded)) ), now).

%!  bulk_write_native(-Boolean) is det.
%
%   Boolean is `true` if write_bytes/2 writes through the foreign
%   library, `false` if it falls back to write/2.

bulk_write_native(B) :-
    native(B),
    !.

%!  write_bytes(+Stream, +Bytes) is det.
%
%   Write the string Bytes, whose code points are bytes (0-255), to
%   Stream. On a binary (octet) stream with the library loaded, what
%   Stream buffered is flushed and Bytes go to its write function in one
%   call; otherwise Bytes are written with write/2. Either way Stream
%   receives exactly Bytes, and is not flushed after them.
%
%   @error representation_error if a code point of Bytes is above 255
%   (with the library loaded).
%   @error io_error(write, Stream) if the write fails.

write_bytes(Stream, Bytes) :-
    (   native(true),
        bulk_write_bytes(Stream, Bytes)
    ->  true
    ;   write(Stream, Bytes)
    ).
