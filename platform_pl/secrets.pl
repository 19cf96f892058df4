:- module(secrets,
          [ check_secrets/3,            % +Host:Port, +Tokens, +Options
            token_entropy_bits/2,       % +Token, -Bits
            loopback_host/1,            % +Host
            take_env_tokens/1,          % -Tokens
            read_token_file/2,          % +File, -Tokens
            text_tokens/2,              % +Text, -Tokens
            token_text_term/2           % +Text, -Token
          ]).
:- autoload(library(option), [option/2]).
:- autoload(library(lists), [member/2]).
:- autoload(library(aggregate), [aggregate_all/3]).
:- autoload(library(error), [must_be/2, domain_error/2]).
:- autoload(library(readutil), [read_file_to_string/3]).
:- autoload(library(apply), [convlist/3]).

/** <module> Secrets strong enough for the network a node listens on

A node's tokens prove a peer's right to send it agents and code; without
TLS its peers' proofs (HMACs of a nonce) cross the network in the clear,
and a weak token falls to an offline search of one captured handshake.
check_secrets/3 is the rule node_start/3 applies; token_entropy_bits/2
its estimate of a token's strength.

Tokens never travel on a command line, which `ps` shows to every user
of the host. A program such as node_main.pl or dfrl_console.pl gets
them in the environment variable `DFRL_TOKEN` (take_env_tokens/1 reads
it and deletes it, so that the program's own children do not inherit
it) or in a file readable by its owner only (`--token-file FILE`,
read_token_file/2). Both hold the token format: one token per line,
surrounding white space and blank lines ignored, a line of ASCII digits
an integer token (as Tartarus tokens are), any other line an atom
(text_tokens/2). The Python side writes and reads the same format
(`experiments/tokens.py`).
*/

%!  check_secrets(+Address, +Tokens, +Options) is det.
%
%   Refuse to listen at Address (Host:Port) with Tokens (the node's, []
%   for an open node) if the address is not loopback, the weakest token
%   has under 128 bits of entropy (token_entropy_bits/2; an open node
%   has 0) and Options (those of node_start/3) hold neither tls(Dir) nor
%   insecure(true). On loopback a weak token is accepted with an
%   informational message, no token at all (an open node, which accepts
%   any agent and any code from any local user) with a warning; off
%   loopback, with insecure(true), either with a warning.
%
%   @error permission_error(listen, address, Address), with context
%   weak_secret(Bits, 128).

check_secrets(Host:Port, Tokens, Options) :-
    (   Tokens == []
    ->  Bits = 0
    ;   aggregate_all(min(B), ( member(T, Tokens), token_entropy_bits(T, B) ), Bits)
    ),
    (   Bits >= 128
    ->  true
    ;   option(tls(_), Options)
    ->  true
    ;   loopback_host(Host)
    ->  (   Tokens == []
        ->  print_message(warning, dfrl(open_node(Host:Port)))
        ;   print_message(informational, dfrl(weak_token(Host:Port, Bits)))
        )
    ;   option(insecure(true), Options)
    ->  print_message(warning, dfrl(insecure_node(Host:Port, Bits)))
    ;   throw(error(permission_error(listen, address, Host:Port),
                    context(node_start/3, weak_secret(Bits, 128))))
    ).

%!  token_entropy_bits(+Token, -Bits) is det.
%
%   An estimate of the entropy of Token: for an integer, its magnitude
%   in bits; for text (atoms, strings, the canonical text of other
%   terms), its length times log2 of the alphabet its characters are
%   drawn from (digits 10, lower case 26, upper case 26, other 33, or
%   hex digits 16), the alphabet being at most the square of the number
%   of distinct characters (so `aaaa...` scores 0). A 64-digit hex
%   string or `dfrl secret`'s output scores over 128.

token_entropy_bits(T, Bits) :-
    integer(T),
    !,
    (   T =:= 0 -> Bits = 0 ; Bits is msb(abs(T)) + 1 ).
token_entropy_bits(T, Bits) :-
    (   ( atom(T) ; string(T) )
    ->  atom_codes(T, Cs)
    ;   format(codes(Cs), '~q', [T])
    ),
    length(Cs, Len),
    sort(Cs, Distinct),
    length(Distinct, D),
    (   forall(member(C, Cs), code_type(C, xdigit(_)))
    ->  Pool0 = 16
    ;   aggregate_all(sum(P), ( char_class(Class, P),
                                once(( member(C, Cs), in_class(Class, C) )) ),
                      Pool0)
    ),
    Pool is min(Pool0, D*D),
    (   Pool =< 1
    ->  Bits = 0
    ;   Bits is floor(Len * log(Pool) / log(2))
    ).

char_class(digit, 10).
char_class(lower, 26).
char_class(upper, 26).
char_class(other, 33).

in_class(digit, C) :- code_type(C, digit).
in_class(lower, C) :- code_type(C, lower), C < 128.
in_class(upper, C) :- code_type(C, upper), C < 128.
in_class(other, C) :- \+ code_type(C, alnum) ; C >= 128.

%!  loopback_host(+Host) is semidet.
%
%   Host (atom or string) names the loopback interface: localhost, ::1
%   or 127.*.

loopback_host(H) :-
    atomic(H),
    atom_string(A, H),
    (   A == localhost
    ->  true
    ;   A == '::1'
    ->  true
    ;   sub_atom(A, 0, _, _, '127.')
    ).


%!  take_env_tokens(-Tokens) is det.
%
%   Tokens are those of the environment variable `DFRL_TOKEN` (text_tokens/2;
%   [] if it is not set), which is then deleted from the environment of
%   this process, so that the processes it starts do not inherit it.

take_env_tokens(Tokens) :-
    (   getenv('DFRL_TOKEN', Text)
    ->  unsetenv('DFRL_TOKEN'),
        text_tokens(Text, Tokens)
    ;   Tokens = []
    ).

%!  read_token_file(+File, -Tokens) is det.
%
%   Tokens are those of File, in the token format (text_tokens/2). Keep
%   the file readable by its owner only (`chmod 600`): `dfrl node` and
%   `dfrl robot` refuse one that other users may read.
%
%   @error existence_error(source_sink, File) if it cannot be read.
%   @error domain_error(token_file, File) if it holds no token.

read_token_file(File, Tokens) :-
    must_be(atomic, File),
    read_file_to_string(File, Text, [encoding(utf8)]),
    text_tokens(Text, Tokens),
    (   Tokens == []
    ->  domain_error(token_file, File)
    ;   true
    ).

%!  text_tokens(+Text, -Tokens) is det.
%
%   Tokens of Text, one per line (token_text_term/2), blank lines
%   skipped.

text_tokens(Text, Tokens) :-
    split_string(Text, "\n", " \t\r", Lines),
    convlist(line_token, Lines, Tokens).

line_token(Line, Token) :-
    Line \== "",
    token_text_term(Line, Token).

%!  token_text_term(+Text, -Token) is det.
%
%   Token is the token Text stands for: an integer if Text is ASCII
%   digits only, else the atom Text.

token_text_term(Text, Token) :-
    atom_codes(Text, Codes),
    (   Codes \== [],
        forall(member(C, Codes), between(0'0, 0'9, C))
    ->  number_codes(Token, Codes)
    ;   atom_codes(Token, Codes)
    ).
