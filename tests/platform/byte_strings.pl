:- module(byte_strings, [byte_string/2]).   % +N, -String

/*  Test data for the plunit suites that move bytes over sockets
    (test_bulk_write.pl, tls_direct_cases.pl).
*/

%!  byte_string(+N, -String) is det.
%
%   String holds N bytes: every byte value in a block of 251 (prime, so
%   the block and the sockets' buffers never line up), repeated.

byte_string(N, String) :-
    numlist(0, 250, Is),
    maplist([I, B]>>(B is (I * 97 + 13) mod 256), Is, Codes),
    string_codes(Block, Codes),
    K is N // 251 + 1,
    length(Blocks, K),
    maplist(=(Block), Blocks),
    atomics_to_string(Blocks, Long),
    sub_string(Long, 0, N, _, String).
