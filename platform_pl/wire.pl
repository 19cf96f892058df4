:- module(wire,
          [ frame_write/3,              % +Stream, +Kind, +Term
            frame_read/3,               % +Stream, -Frame, +Options
            wire_version/1,             % -Version
            text_term_bytes/2,          % ?Term, ?Bytes
            term_depth_within/2         % @Term, +MaxDepth
          ]).
:- use_module(platform_errors, [wire_error/1]).
:- autoload(library(utf8), [utf8_codes//1]).
:- autoload(library(lists), [append/3]).
:- autoload(library(error), [must_be/2]).
:- autoload(library(option), [option/3]).
:- autoload(library(memfile),
            [ new_memory_file/1, open_memory_file/4, free_memory_file/1 ]).

/** <module> Length-prefixed frames on a binary stream

A frame is a 12-byte header followed by a body:

  | bytes | meaning                                        |
  |-------|------------------------------------------------|
  | 0-3   | magic "DFRL"                                   |
  | 4     | protocol version (1)                           |
  | 5     | kind: "T" (text term) or "B" (binary term)     |
  | 6-7   | reserved, zero                                 |
  | 8-11  | body length in bytes, unsigned big-endian      |

Both kinds carry their real body length, and frame_read/3 checks it
against a limit before a single body byte is read, so a proxy or a test
can count and cut frames without decoding them. A text body is the term
written canonically (UTF-8) and is read back with read_term/3, so any
peer may send one. A binary body is the term as fast_term_serialized/2
writes it (SWI-Prolog's fast serialization): it is quick for large float
lists, but the C reader trusts its input and crashes the process on
garbage, so frame_read/3 accepts a binary frame only when the caller says
the connection is authenticated (the peer proved a token of this node).
A binary body is read whole (exactly its length) before it is decoded.

Before a peer has authenticated, a server reads with three more limits
(options of frame_read/3): the whole frame, from its first byte to its
last, must arrive within a deadline (deadline(Sec)); the peer sends one
frame and waits for its answer (no pipelining before authentication);
and the parsed term may be at most max_depth(D) deep (a list counts as
one level, whatever its length; an operator chain such as `a+a+...+a`
is as deep as it is long). read_term/3 parses in time linear in the
text for every shape tried (chains of infix, prefix and mixed
operators, nested brackets; deeply nested brackets raise a resource
error, reported as a syntax error), and every check after it is linear
too, so a frame's cost is bounded by its size.
*/

wire_version(1).

magic([0'D, 0'F, 0'R, 0'L]).

kind_byte(text,   0'T).
kind_byte(binary, 0'B).

%!  frame_write(+Stream, +Kind, +Term) is det.
%
%   Write Term as one frame of Kind (`text` or `binary`) and flush.

frame_write(Stream, Kind, Term) :-
    body_bytes(Kind, Term, Body),
    string_length(Body, Len),
    (   Len > 0xffffffff
    ->  wire_error(too_large(Len, 0xffffffff))
    ;   true
    ),
    write_header(Stream, Kind, Len),
    write(Stream, Body),
    flush_output(Stream).

write_header(Stream, Kind, Len) :-
    kind_byte(Kind, K),
    wire_version(V),
    magic(M),
    forall(member(B, M), put_byte(Stream, B)),
    put_byte(Stream, V),
    put_byte(Stream, K),
    put_byte(Stream, 0),
    put_byte(Stream, 0),
    put_u32(Stream, Len).

body_bytes(text, Term, Body) :-
    text_term_bytes(Term, Codes),
    string_codes(Body, Codes).
body_bytes(binary, Term, Body) :-
    fast_term_serialized(Term, Body).

%!  text_term_bytes(?Term, ?Bytes) is det.
%
%   Bytes is the UTF-8 encoding of Term written canonically and
%   terminated by " .". In mode (-,+) the term is read with read_term/3;
%   a syntax error raises wire_error(syntax(Detail)).

text_term_bytes(Term, Bytes) :-
    var(Bytes),
    !,
    format(string(Text), "~k .~n", [Term]),
    string_codes(Text, Codes),
    phrase(utf8_codes(Codes), Bytes).
text_term_bytes(Term, Bytes) :-
    (   phrase(utf8_codes(Codes), Bytes)
    ->  true
    ;   wire_error(syntax(not_utf8))
    ),
    setup_call_cleanup(
        open_codes_stream(Codes, In),
        read_text_term(In, Term),
        close(In)).

read_text_term(In, Term) :-
    catch(read_term(In, Term0, [syntax_errors(error)]), E, bad_syntax(E)),
    (   Term0 == end_of_file
    ->  wire_error(syntax(empty))
    ;   true
    ),
    catch(read_term(In, Rest, [syntax_errors(error)]), E2, bad_syntax(E2)),
    (   Rest == end_of_file
    ->  Term = Term0
    ;   wire_error(syntax(trailing_data))
    ).

bad_syntax(error(syntax_error(What), _)) :-
    !,
    wire_error(syntax(What)).
bad_syntax(error(resource_error(What), _)) :-
    !,
    wire_error(syntax(resource_error(What))).
bad_syntax(E) :-
    throw(E).

open_codes_stream(Codes, In) :-
    string_codes(String, Codes),
    open_string(String, In).

%!  frame_read(+Stream, -Frame, +Options) is det.
%
%   Read one frame. Frame is frame(Kind, Term), or `end_of_file` if the
%   peer closed the connection between frames. Options:
%
%     - max_size(+Bytes)
%       Largest body accepted (default 1 MiB).
%     - binary(+Boolean)
%       Whether binary frames are accepted (default `false`).
%     - deadline(+Seconds)
%       The frame must be complete within Seconds of its first byte (the
%       stream's own timeout bounds the wait for that first byte). The
%       frame is read in chunks, each read with the time that is left,
%       so a peer trickling bytes cannot hold the reader longer; bytes
%       beyond the frame are an error (pipelined), as the caller has not
%       answered yet. For unauthenticated peers.
%     - max_depth(+Depth)
%       The text term may be at most Depth deep (term_depth_within/2).
%
%   @error wire_error(Reason) for a malformed, oversized, late or
%   refused frame.

frame_read(Stream, Frame, Options) :-
    option(max_size(Max), Options, 1048576),
    option(binary(AllowBinary), Options, false),
    (   option(deadline(Secs), Options, none), Secs \== none
    ->  read_frame_deadline(Stream, Max, AllowBinary, Secs, Frame0)
    ;   read_frame_plain(Stream, Max, AllowBinary, Frame0)
    ),
    (   Frame0 = frame(text, Term),
        option(max_depth(Depth), Options, none), Depth \== none,
        \+ term_depth_within(Term, Depth)
    ->  wire_error(too_deep(Depth))
    ;   Frame = Frame0
    ).

read_frame_plain(Stream, Max, AllowBinary, Frame) :-
    get_byte(Stream, B0),
    (   B0 == -1
    ->  Frame = end_of_file
    ;   read_bytes(Stream, 11, Rest),
        Header = [B0|Rest],
        check_header(Header, Max, AllowBinary, Kind, Len),
        read_body(Stream, Len, Body),
        decode_body(Kind, Body, Term),
        Frame = frame(Kind, Term)
    ).

check_header(Header, Max, AllowBinary, Kind, Len) :-
    parse_header(Header, Kind, Len),
    (   Len > Max
    ->  wire_error(too_large(Len, Max))
    ;   true
    ),
    (   Kind == binary, AllowBinary \== true
    ->  wire_error(binary_not_allowed)
    ;   true
    ).

%   The deadline reader: chunks of what the stream has (read_chunk/2),
%   each wait bounded by the time left.
read_frame_deadline(Stream, Max, AllowBinary, Secs, Frame) :-
    read_chunk(Stream, First),
    (   First == []
    ->  Frame = end_of_file
    ;   get_time(T0),
        Deadline is T0 + Secs,
        length(First, N0),
        fill_to(Stream, 12, First, N0, Deadline, Secs, Got, NGot),
        length(Header, 12),
        append(Header, _, Got),
        check_header(Header, Max, AllowBinary, Kind, Len),
        Need is 12 + Len,
        fill_to(Stream, Need, Got, NGot, Deadline, Secs, All, NAll),
        (   NAll > Need
        ->  wire_error(pipelined)
        ;   true
        ),
        append(Header, BodyCodes, All),
        string_codes(Body, BodyCodes),
        decode_body(Kind, Body, Term),
        Frame = frame(Kind, Term)
    ).

%   fill_to(+Stream, +Need, +Have, +NHave, +Deadline, +Secs, -All, -NAll):
%   read until at least Need bytes are there.
fill_to(_, Need, Have, N, _, _, Have, N) :-
    N >= Need,
    !.
fill_to(Stream, Need, Have, N, Deadline, Secs, All, NAll) :-
    get_time(Now),
    Left is Deadline - Now,
    (   Left =< 0
    ->  wire_error(deadline(Secs))
    ;   true
    ),
    set_stream(Stream, timeout(Left)),
    catch(read_chunk(Stream, More),
          error(timeout_error(_, _), _),
          wire_error(deadline(Secs))),
    (   More == []
    ->  wire_error(truncated)
    ;   true
    ),
    length(More, M),
    append(Have, More, Have1),
    N1 is N + M,
    fill_to(Stream, Need, Have1, N1, Deadline, Secs, All, NAll).

%   What the stream has: its buffer, or one read(2) (waiting at most the
%   stream's timeout) if the buffer is empty; [] at end of file.
read_chunk(Stream, Codes) :-
    fill_buffer(Stream),
    read_pending_codes(Stream, Codes, []).

%!  term_depth_within(@Term, +MaxDepth) is semidet.
%
%   True if Term is at most MaxDepth deep: an atomic term or a variable
%   has depth 0, a compound one more than its deepest argument, except
%   that the elements of a list are all one level below the list,
%   however long it is. Linear in the size of Term; gives up as soon as
%   MaxDepth is exceeded.

term_depth_within(Term, Max) :-
    must_be(nonneg, Max),
    depth_ok(Term, Max).

depth_ok(T, _) :-
    \+ compound(T),
    !.
depth_ok(T, Left) :-
    Left > 0,
    Left1 is Left - 1,
    (   T = [_|_]
    ->  list_ok(T, Left1)
    ;   compound_name_arity(T, _, A),
        args_ok(1, A, T, Left1)
    ).

list_ok(L, Left) :-
    (   compound(L), L = [H|T]
    ->  depth_ok(H, Left),
        list_ok(T, Left)
    ;   depth_ok(L, Left)
    ).

args_ok(I, A, _, _) :-
    I > A,
    !.
args_ok(I, A, T, Left) :-
    arg(I, T, X),
    depth_ok(X, Left),
    I1 is I + 1,
    args_ok(I1, A, T, Left).

parse_header([M0,M1,M2,M3,V,K,_,_,L0,L1,L2,L3], Kind, Len) :-
    (   magic([M0,M1,M2,M3])
    ->  true
    ;   wire_error(bad_magic)
    ),
    (   wire_version(V)
    ->  true
    ;   wire_error(bad_version(V))
    ),
    (   kind_byte(Kind, K)
    ->  true
    ;   wire_error(protocol(kind(K)))
    ),
    Len is (L0<<24) \/ (L1<<16) \/ (L2<<8) \/ L3.

read_bytes(_, 0, []) :- !.
read_bytes(Stream, N, [B|Bs]) :-
    get_byte(Stream, B),
    (   B == -1
    ->  wire_error(truncated)
    ;   true
    ),
    N1 is N - 1,
    read_bytes(Stream, N1, Bs).

read_body(Stream, Len, Body) :-
    read_string(Stream, Len, Body),
    string_length(Body, Got),
    (   Got =:= Len
    ->  true
    ;   wire_error(truncated)
    ).

%   A text body (a string of bytes) is decoded as UTF-8 through a memory
%   file: no list of codes is built, so a large frame costs about its own
%   size in memory, not twenty times that.
decode_body(text, Body, Term) :-
    setup_call_cleanup(
        new_memory_file(MF),
        ( setup_call_cleanup(open_memory_file(MF, write, W, [encoding(octet)]),
                             write(W, Body),
                             close(W)),
          setup_call_cleanup(open_memory_file(MF, read, In, [encoding(utf8)]),
                             read_text_term(In, Term),
                             close(In))
        ),
        free_memory_file(MF)).
decode_body(binary, Body, Term) :-
    (   catch(fast_term_serialized(Term0, Body), _, fail)
    ->  Term = Term0
    ;   wire_error(syntax(binary))
    ).

put_u32(Stream, N) :-
    B0 is (N >> 24) /\ 0xff,
    B1 is (N >> 16) /\ 0xff,
    B2 is (N >> 8) /\ 0xff,
    B3 is N /\ 0xff,
    put_byte(Stream, B0),
    put_byte(Stream, B1),
    put_byte(Stream, B2),
    put_byte(Stream, B3).
